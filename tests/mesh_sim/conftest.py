"""Fixtures shared by the benchmark tests."""

from __future__ import annotations

import io
import tempfile

import pytest
from rich.console import Console


@pytest.fixture
def private_tmp(tmp_path, monkeypatch):
    """Temporary folders of the code under test go here, so the test can check they were removed."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


@pytest.fixture
def printed():
    """``printed(module, result)``: what a benchmark's ``report`` prints for ``result``."""

    def render(module, result, width: int = 220) -> str:
        out = io.StringIO()
        module.report(result, Console(file=out, width=width))
        return out.getvalue()

    return render
