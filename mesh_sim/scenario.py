"""A whole scenario: the agents' part (``agent.config``) plus the world's targets.

Scenarios are TOML files; the ones shipped with skymesh live in ``mesh_sim/scenarios`` and are named
by their stem (``skymesh run --scenario default``); any other path is read as a file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from agent.config import AgentScenario, check_seed, read_scenario_file
from agent.net.fire_truth import decoy
from mesh_sim.fire import FireConfig
from mesh_sim.radio import compile_plan
from mesh_sim.target_set import targets_from_config
from perception.terrain import terrain_from_config

SCENARIO_DIR = Path(__file__).with_name("scenarios")


@dataclass(frozen=True)
class References:
    """``[references]``: which centralized filters the world runs beside the fleet (:mod:`mesh_sim.oracle`).

    The oracle itself always runs: every run's RMSE ratio is to it. ``imm`` adds the consistent IMM
    reference (``imm_targets``), ``in_flight`` the in-flight oracle — one centralized tracker per agent, so
    N trackers in the world process, which on a small machine takes cores from the agents it measures.
    Both are on by default; ``skymesh bench scale`` turns them off."""

    imm: bool = True
    in_flight: bool = True

    @classmethod
    def from_dict(cls, d) -> References:
        if not isinstance(d, dict):
            raise ValueError(f"[references] must be a table, got {d!r}")
        unknown = set(d) - {"imm", "in_flight"}
        if unknown:
            raise ValueError(f"unknown references settings: {sorted(unknown)} (known: imm, in_flight)")
        for key, value in d.items():
            if not isinstance(value, bool):
                raise ValueError(f"references.{key} must be true or false, got {value!r}")
        return cls(**d)


@dataclass(frozen=True)
class Scenario:
    path: Path
    raw: dict
    agent: AgentScenario
    targets: list
    fire: FireConfig | None = None  # [fire]: the true fire (mesh_sim.fire); None: no fire
    decoys: tuple = ()  # (north, east, probability per frame) hot spots that are not fires
    references: References = References()  # [references]: the centralized filters the world runs

    @property
    def name(self) -> str:
        return self.agent.name


def shipped() -> list[str]:
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))


def resolve(name_or_path: str) -> Path:
    """A shipped scenario by name, or a TOML file by path."""
    candidate = SCENARIO_DIR / f"{name_or_path}.toml"
    if "/" in name_or_path or name_or_path.endswith((".toml", ".json")):
        candidate = Path(name_or_path)
    if candidate.is_file():
        return candidate
    path = Path(name_or_path)
    if path.is_file():
        return path
    raise ValueError(f"no scenario {name_or_path!r}: not a file, and not one of {shipped()}")


#: The kind a section has when it does not name one.
_DEFAULT_KINDS = {"sensor": "bearing", "tasking": "placeholder"}
_KIND_KEYS = {"tasking": "planner"}  # the key that names what a section builds (else "kind")


def _same_kind(section: str, current: dict, override: dict) -> bool:
    key = _KIND_KEYS.get(section, "kind")
    if key not in override:
        return True
    return override[key] == current.get(key, _DEFAULT_KINDS.get(section))


def load(name_or_path: str, **overrides) -> Scenario:
    """Load and validate a scenario. ``overrides`` replace top-level settings (``agents=8``) or merge into
    a section (``tracking={"policy": "ci"}`` changes only the policy). A section override that names a
    different ``kind`` replaces the section (``sensor={"kind": "camera"}`` on a scenario with geometric
    bearings: the bearing settings do not apply to a camera; likewise ``tasking={"planner": ...}`` naming another
    planner)."""
    path = resolve(name_or_path)
    raw = read_scenario_file(path)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(raw.get(key), dict) and _same_kind(key, raw[key], value):
            raw[key] = {**raw[key], **value}
        elif value is not None:
            raw[key] = value
    try:
        if "radio" in raw:
            agents = [f"uav{i}" for i in range(int(raw.get("agents", AgentScenario.agents)))]
            raw["radio_plan"] = compile_plan(raw["radio"], agents, check_seed(raw.get("seed", AgentScenario.seed)))
        agent = AgentScenario.from_dict(raw)
        targets = targets_from_config(raw.get("targets", []), terrain_from_config(agent.terrain))
        fire = FireConfig.from_dict(raw["fire"], agent.area.as_tuple()) if "fire" in raw else None
        decoys = parse_decoys(raw.get("decoys", []))
        references = References.from_dict(raw.get("references", {}))
        if fire is not None and agent.grid is None:
            raise ValueError("[fire] needs a [grid] section: the agents map the fire with certainty grids")
    except (ValueError, TypeError, KeyError) as err:
        raise ValueError(f"{path}: {err}") from None
    return Scenario(path, raw, agent, targets, fire, decoys, references)


def parse_decoys(entries) -> tuple[tuple[float, float, float], ...]:
    """``decoys = [[north, east, probability], ...]``: each a finite position and a probability in [0, 1]."""
    if not isinstance(entries, list):
        raise ValueError(f"decoys must be a list of [north, east, probability], got {entries!r}")
    out = []
    for k, entry in enumerate(entries):
        parsed = decoy(entry)
        if parsed is None:
            raise ValueError(f"decoys[{k}] must be [north, east, probability in 0..1], got {entry!r}")
        out.append(parsed)
    return tuple(out)

