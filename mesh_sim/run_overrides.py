"""The scenario settings ``skymesh run``'s flags override, and the blame for a bad value: the flag, not the file.

``skymesh run --duration 0`` used to say ``…/default.toml: duration must be a positive number``: the scenario file
is fine, the flag is not. So the scenario is first loaded as it is (a bad file is the file's fault and says so),
then with each flag's override alone (the first that fails is named, with the value given), then with all of them.
"""

from __future__ import annotations

import argparse

from mesh_sim.scenario import Scenario, load

#: flag -> (the scenario setting it overrides, its section or None for a top-level setting)
FLAGS = {"--agents": ("agents", None), "--duration": ("duration", None), "--seed": ("seed", None),
         "--policy": ("policy", "tracking"), "--topology": ("topology", "radio"), "--loss": ("loss", "radio"),
         "--latency": ("delay_ms", "radio"), "--bandwidth": ("rate", "radio")}


def given(args: argparse.Namespace) -> dict[str, object]:
    """The override flags the user gave, by flag: ``{"--duration": 0.0}``."""
    values = {flag: getattr(args, flag.removeprefix("--")) for flag in FLAGS}
    return {flag: value for flag, value in values.items() if value is not None}


def overrides(flags: dict[str, object]) -> dict:
    """The scenario loader's overrides for ``flags`` (:func:`mesh_sim.scenario.load`): top-level settings by name,
    section settings merged into their section (``{"radio": {"loss": 0.3}}``)."""
    out: dict = {}
    for flag, value in flags.items():
        setting, section = FLAGS[flag]
        if section is None:
            out[setting] = value
        else:
            out.setdefault(section, {})[setting] = value
    return out


def load_with_flags(scenario: str, flags: dict[str, object]) -> Scenario:
    """``scenario`` with ``flags`` applied; a ``ValueError`` names the file when the file is bad, else the first
    flag whose value is bad (``--loss 1.5: radio: loss: must be <= 1, got 1.5``)."""
    base = load(scenario)
    for flag, value in flags.items():
        try:
            load(scenario, **overrides({flag: value}))
        except ValueError as err:
            raise ValueError(f"{flag} {value}: {str(err).removeprefix(f'{base.path}: ')}") from None
    return load(scenario, **overrides(flags))
