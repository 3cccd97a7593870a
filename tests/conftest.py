"""Test-wide settings. In CI (``CI`` set, as ``.ci/run`` runs) hypothesis draws its examples from a fixed
seed, so a red CI is reproducible and never a lottery; locally every run explores new examples."""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True)
if os.environ.get("CI"):
    settings.load_profile("ci")
