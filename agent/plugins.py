"""The agent's seams (DESIGN.md §4), written as code: the agent is a host for these plug-ins.

Each family lives in one folder with a registry, and the loop (:mod:`agent.agent`) names none of its
implementations — in the style of Stone Soup's tiny ``base.py`` per component family:

============== ============================================ =======================================
seam           protocol                                     implementations (folder: registry)
============== ============================================ =======================================
belief         :class:`fusion.belief.Belief`                 ``fusion/``: Gaussian, Trajectory, grids
sensor         :class:`Sensor`                              ``agent/sensors/``: ``SENSORS``
exchange       :class:`BeliefExchange`                      ``agent/beliefs/``: ``EXCHANGES``
planner        :class:`tasking.base.Planner`                ``tasking/``: ``tasking.registry.PLANNERS``
vehicle        :class:`agent.vehicles.base.Vehicle`         ``agent/vehicles/``
transport      :class:`Transport`                           ``agent/net/``: Zenoh, bus, radio wrapper
============== ============================================ =======================================

One step of the host: read the vehicle; every sensor measures (simulated ones first get the step's
:class:`~agent.sensors.truth.TruthSnapshot`); every exchange absorbs the observations it uses; received
messages are dispatched to the exchange of their kind; telemetry goes out; every exchange offers its
message; the planner turns the exchanges' views into a goal, whose gimbal command (``look_at``) every sensor
is handed (:meth:`Sensor.point`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Protocol

from agent.net.keys import Incoming
from agent.sensors.truth import TruthSnapshot
from fusion.resync import Edge

#: Observations of one step, by name: ``"bearings"`` (a list of :class:`agent.sensors.bearing.Bearing`),
#: ``"fire_evidence"`` (a thermal frame's cell evidence), ...
Observations = Mapping[str, object]


def merge_observations(into: dict, more: Mapping[str, object]) -> None:
    """Add one sensor's observations to the step's: lists of the same name are joined (two sensors that both
    give ``"bearings"``, e.g. the ``[sensor]`` camera and the thermal camera's hot spots); any other name may
    come from one sensor only (``ValueError`` names it)."""
    for name, value in more.items():
        if name not in into:
            into[name] = value
        elif isinstance(into[name], list) and isinstance(value, list):
            into[name] = into[name] + value
        else:
            raise ValueError(f"two sensors give the observation {name!r}, which cannot be joined (not lists)")


class Transport(Protocol):
    """Bytes on keys (DESIGN.md §5): :class:`agent.net.zenoh_transport.ZenohTransport`,
    :class:`agent.net.bus.BusEndpoint`, or either inside :class:`agent.net.radio.RadioTransport`."""

    dropped: int  # times received samples may have been lost because the agent fell behind (see each transport)

    def publish(self, key: str, data: bytes) -> None: ...

    def drain(self) -> Iterable[Incoming]: ...

    def alive(self) -> set[str]: ...

    def close(self) -> None: ...


class Sensor(Protocol):
    """Observations from the vehicle state. A simulated sensor draws them from the truth it was given
    (:meth:`on_truth`, called before every :meth:`measure`); a real one ignores it."""

    def on_truth(self, truth: TruthSnapshot) -> None: ...

    def measure(self, t: float, state) -> Observations: ...

    def point(self, look_at) -> None:
        """The planner's gimbal command of this step (``tasking.orbit.Goal.look_at``: a NED point, or ``None``),
        for the next measurements; a sensor without a steerable gimbal ignores it."""
        ...

    def telemetry(self) -> dict: ...

    def metrics(self) -> dict: ...

    def close(self) -> None: ...


@dataclass
class Outgoing:
    """A message an exchange offers. ``prepaid``: the exchange already charged the link budget (entry by
    entry); otherwise the host admits the whole envelope against it. ``context``: the exchange's own record
    of what it offered, handed back with the message to :meth:`BeliefExchange.sent`."""

    payload: dict
    prepaid: bool = False
    context: object = None


class Outbox(Protocol):
    """What the host lends an exchange to reach the simulator (raw data for the centralized references:
    simulation only, counted apart from radio traffic)."""

    def to_simulator(self, kind: str, t: float, payload: dict) -> None: ...


class BeliefExchange(Protocol):
    """One wire kind of belief (``"track"``, ``"grid"``; later ``"particles"``): it owns the local belief,
    its channel filters and its codec."""

    kind: str
    #: Does :meth:`receive` read ``edge``? The agent asks the topology only for exchanges that do: the bridge test
    #: rebuilds the known graph (O(N^2) for N agents) whenever it changed, and a 40-agent full mesh changes it about
    #: twice a step — a tenth of a flood agent's step, for an answer flooding and CBBA never read.
    needs_edge: bool

    def sensors(self) -> list[Sensor]:
        """Sensors this belief brings to the agent beyond the ``[sensor]`` section's (e.g. a thermal camera)."""
        ...

    def planning_hints(self) -> dict:
        """Facts a planner of this belief needs when it is built (:class:`tasking.registry.PlanningContext`)."""
        ...

    def absorb(self, t: float, observations: Observations) -> None:
        """Update the local belief with this step's observations."""
        ...

    def outgoing(self, t: float, neighbours: list[str]) -> Outgoing | None:
        """The message to broadcast now (``None``: nothing due)."""
        ...

    def sent(self, seq: int, message: Outgoing) -> None:
        """``message`` left as envelope ``seq``: channel filters may now count on acknowledgements of it."""
        ...

    def thinned(self, message: Outgoing) -> None:
        """``message`` did not fit the link budget and was not sent."""
        ...

    def receive(self, origin: str, seq: int, stamp: float, payload: dict, edge: Edge | None,
                t: float) -> list[tuple[str, str | None]]:
        """Decode and fuse a peer's message (``edge``: what the link to ``origin`` is in the known graph,
        :meth:`agent.net.topology.Topology.edge`, or ``None`` when :attr:`needs_edge` is false); returns
        ``(method, cause)`` per belief fused, the cause of a fusion that was not exact
        (:data:`fusion.channel_filter.CAUSES`) or ``None``. Raises :class:`agent.net.wire.DecodeError` on a bad
        message, and then changes nothing."""
        ...

    def settle(self, t: float) -> None:
        """Every message of this step has been received: apply what :meth:`receive` held back to apply
        together (e.g. the flood policy's detections, :mod:`agent.beliefs.flood`)."""
        ...

    def view(self) -> object:
        """A read-only view for planners (:mod:`tasking.base`)."""
        ...

    def telemetry(self) -> dict:
        """What the ground station sees of this belief."""
        ...

    def evaluate(self, t: float, truth: TruthSnapshot) -> None:
        """Score the belief against the truth (simulation only)."""
        ...

    def metrics(self) -> dict: ...


class Views(Mapping):
    """The exchanges' views for the planner, each computed only if the planner reads it."""

    def __init__(self, exchanges: dict):
        self._exchanges = exchanges

    def __getitem__(self, kind: str):
        return self._exchanges[kind].view()

    def __iter__(self) -> Iterator[str]:
        return iter(self._exchanges)

    def __len__(self) -> int:
        return len(self._exchanges)
