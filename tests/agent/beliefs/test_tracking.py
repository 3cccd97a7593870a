"""Multi-target bearing-only tracking (agent.beliefs.tracking) against known truth, through the real sensor model.

Every scenario draws its bearings with ``GeometricBearingSensor`` from cameras at about 80 m altitude
(NED, z down) looking at targets on flat ground (z = 0), on the tracker's 0.2 s grid:

* crossing targets keep their track identities (gated Hungarian scan-to-track, Merino (3.64), spec §3.9);
* clutter starts tentative tracks that die on schedule; the real targets end up as the confirmed ones;
* a track started from one bearing has an honest covariance (NEES of the ray-to-terrain initiation);
* peers' tracks are matched (Merino (3.65)) through a persistent remote -> local label table, or adopted;
* tracks nobody measures are deleted after ``stale_after``, whatever peers keep echoing;
* duplicate tracks of one target are dropped when confirmed, or merged (with their labels) when fused;
* on a tree of two agents, exact channel filters reproduce the centralized belief.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import stats

from agent.beliefs.tracking import STATE_DIM, RemoteTrack, Tracker
from agent.beliefs.tracking_config import TrackerConfig
from agent.sensors.bearing import BearingSensorConfig, GeometricBearingSensor
from fusion.gaussian import UninformativeBeliefError
from fusion.measurement import Bearing3D
from fusion.trajectory import Trajectory
from perception.terrain import FlatTerrain

STEP = 0.2  # [s] the tracker's grid and the sensors' frame period
GROUND = FlatTerrain(0.0)
ALTITUDE = -80.0  # NED z of the cameras


def clean_sensor(seed: int, **kw) -> GeometricBearingSensor:
    """The real sensor model (1 degree noise, 90 degree cone, 250 m range), no misses and no clutter."""
    return GeometricBearingSensor(BearingSensorConfig(p_detect=1.0, false_alarms=0.0, **kw), seed)


def static(tid: str, north: float, east: float):
    position = np.array([north, east, 0.0])
    return lambda t: {"id": tid, "position": position}


def broadcast(tracker: Tracker, seq: int) -> list[tuple]:
    """Message ``seq`` as ``agent.agent`` builds it: every confirmed track with its per-peer acknowledgements."""
    tracks = tracker.confirmed()
    tracker.record_sent(tracks, seq)
    return [(t.id, t.belief, t.last_measured, dict(t.acks)) for t in tracks]


def received(entries: list[tuple], me: str) -> list[RemoteTrack]:
    """A message as receiver ``me`` decodes it: each track carries the seq of *my* message its sender fused."""
    return [RemoteTrack(tid, belief, last, acks.get(me)) for tid, belief, last, acks in entries]


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def nearest(tracker: Tracker, position) -> tuple[int, float]:
    """The confirmed track nearest to ``position`` and its distance [m]."""
    dist = {tid: float(np.linalg.norm(est.mean[:3] - position)) for tid, est in tracker.estimates()}
    tid = min(dist, key=dist.get)
    return tid, dist[tid]


class Link:
    """Two trackers on one (tree) link exchanging every confirmed track every time, as ``agent.agent`` does
    without a link budget: messages carry sequence numbers, tracks their per-peer acknowledgements."""

    def __init__(self, a: Tracker, b: Tracker):
        self.trackers = {"A": a, "B": b}
        self.seq = {"A": 0, "B": 0}

    def send(self, name: str) -> tuple:
        self.seq[name] += 1
        return broadcast(self.trackers[name], self.seq[name]), self.seq[name]

    def deliver(self, to: str, frm: str, msg: tuple) -> list:
        entries, seq = msg
        return self.trackers[to].fuse_remote(frm, received(entries, to), seq)

    def exchange(self) -> None:
        """Both send at once, then each fuses the other's message."""
        from_a, from_b = self.send("A"), self.send("B")
        self.deliver("B", "A", from_a)
        self.deliver("A", "B", from_b)


# -- 1. crossing targets ---------------------------------------------------------------------------------------


class RecordingTracker(Tracker):
    """Records, per scan, which truth label each assigned detection carried and the gated costs."""

    def __init__(self, *args):
        super().__init__(*args)
        self.scans: list[tuple[int, list[tuple[str, int]], np.ndarray]] = []
        self.dropped = 0  # tracks dropped as duplicates when they were confirmed

    def _duplicate(self, track):
        duplicate = super()._duplicate(track)
        self.dropped += duplicate
        return duplicate

    def _pairs_by_distance(self, bearings):
        pairs = super()._pairs_by_distance(bearings)
        if bearings and self.tracks:
            cost = np.array(self._distances(bearings)[1])
            labels = [(bearings[i].truth_id, track_id) for i, track_id in pairs]
            self.scans.append((self.epoch, labels, cost))
        return pairs


def crossing(t: float) -> list[dict]:
    """A heads north-east, B south-east at 4.2 m/s each; they pass 4 m apart at t = 10 s, at (0, 0)."""
    a = np.array([-30.0, -30.0, 0.0]) + t * np.array([3.0, 3.0, 0.0])
    b = np.array([-26.0, 30.0, 0.0]) + t * np.array([3.0, -3.0, 0.0])
    return [{"id": "A", "position": a}, {"id": "B", "position": b}]


CROSSING_CAMERAS = [np.array([0.0, -40.0, ALTITUDE]), np.array([0.0, 40.0, ALTITUDE]), np.array([-40.0, 0.0, ALTITUDE])]


@pytest.mark.parametrize(("seed", "duplicate"), [(0, False), (7, False), (13, True)])
def test_crossing_targets_keep_one_track_each_and_their_identities(seed, duplicate):
    """Three cameras, one scan each per step. Before the crossing (t = 5 s, 30 m apart) each target has a
    confirmed track; after it (t = 19.8 s, 59 m apart) those same two tracks are the only confirmed ones, each within
    3 m of its own target, and every detection assigned to them after the crossing carried their target's
    label. The crossing is a real test: in some scans both detections are nearest (in ``d^2``) to one track,
    so per-detection nearest neighbour would give one track both detections and leave the other without.

    About 1 % of a target's detections fall outside its gate (``d^2 > 9``) and start tentative tracks; with
    seed 13, three of A's detections between t = 3.4 and 4.0 s do and confirm one: it is dropped as a duplicate.
    (Residual: in 2 of 80 seeds such a duplicate is confirmed outside the track-to-track gate and stays.)"""
    sensors = [clean_sensor(100 * seed + i) for i in range(len(CROSSING_CAMERAS))]
    tracker = RecordingTracker(TrackerConfig(), STEP, GROUND)
    identity = {}
    for k in range(100):
        t = k * STEP
        tracker.advance(k)
        truth = crossing(t)
        for sensor, camera in zip(sensors, CROSSING_CAMERAS, strict=True):
            tracker.update(sensor.detect(t, camera, truth))
        if k == 25:
            assert len(tracker.estimates()) == 2
            for target in truth:
                identity[target["id"]], error = nearest(tracker, target["position"])
                assert error < 3.0
            assert identity["A"] != identity["B"]

    assert (tracker.dropped > 0) == duplicate
    assert sorted(tid for tid, _ in tracker.estimates()) == sorted(identity.values())
    for target in crossing(99 * STEP):
        est = tracker.tracks[identity[target["id"]]].estimate()
        assert np.linalg.norm(est.mean[:3] - target["position"]) < 3.0, target["id"]

    contested = 0
    for epoch, labels, cost in tracker.scans:
        assert len({track for _, track in labels}) == len(labels)  # never two detections on one track
        if epoch >= 60:  # after the crossing: the same tracks get their own target's detections
            for label, track in labels:
                if track in identity.values():
                    assert track == identity[label], (epoch, label, track)
        gated = cost <= tracker.config.gate
        if len(labels) < 2 or not epoch > 25:
            continue
        first, second = np.argmin(cost, axis=1)
        if first == second and gated[0, first] and gated[1, first]:
            contested += 1  # both detections nearest to one track, yet each went to a track of its own
    assert contested > 0


# -- 2. false alarms -------------------------------------------------------------------------------------------

CLUTTER_TARGETS = [static("T1", -15.0, 10.0), static("T2", 20.0, -12.0)]


def orbiting_camera(i: int, t: float) -> np.ndarray:
    angle = 0.15 * t + np.pi * i
    return np.array([25.0 * np.cos(angle), 25.0 * np.sin(angle), ALTITUDE])


def run_clutter(false_alarms: float, seed: int, seconds: float = 30.0) -> dict:
    """Two orbiting cameras, p_detect 0.9, ``false_alarms`` clutter detections per frame each."""
    config = BearingSensorConfig(p_detect=0.9, false_alarms=false_alarms)
    sensors = [GeometricBearingSensor(config, 7 * seed + i) for i in range(2)]
    tracker = Tracker(TrackerConfig(), STEP, GROUND)
    most_confirmed = most_tracks = candidates = 0
    initiated = []
    for k in range(int(round(seconds / STEP))):
        t = k * STEP
        tracker.advance(k)
        truth = [target(t) for target in CLUTTER_TARGETS]
        initiated.append(0)
        for i, sensor in enumerate(sensors):
            counts = tracker.update(sensor.detect(t, orbiting_camera(i, t), truth))
            initiated[-1] += counts["initiated"]
            candidates += counts["candidate"]
        for track in tracker.tracks.values():  # a tentative track lives at most confirm_within epochs
            assert track.confirmed or tracker.epoch - track.created_epoch < tracker.config.confirm_within
        tentative = sum(not track.confirmed for track in tracker.tracks.values())
        assert tentative <= sum(initiated[-tracker.config.confirm_within:])
        most_confirmed = max(most_confirmed, len(tracker.estimates()))
        most_tracks = max(most_tracks, len(tracker.tracks))
    errors = [nearest(tracker, target(0.0)["position"])[1] for target in CLUTTER_TARGETS]
    return {"tracker": tracker, "most_confirmed": most_confirmed, "most_tracks": most_tracks, "errors": errors,
            "initiated": sum(initiated), "candidates": candidates}


def test_moderate_clutter_leaves_exactly_the_two_targets_confirmed():
    """0.2 false alarms per frame and camera (4x the default) and p_detect 0.9 for 30 s: clutter starts
    tracks, none of them is ever confirmed, and the two targets end as the only confirmed tracks (< 3 m)."""
    run = run_clutter(0.2, seed=1)
    assert run["candidates"] > 20  # clutter did reach initiation (held as candidates: agent.beliefs.track_candidates)
    assert len(run["tracker"].estimates()) == 2
    assert run["most_confirmed"] == 2
    assert max(run["errors"]) < 3.0


@pytest.fixture(scope="module")
def heavy_clutter() -> dict:
    return run_clutter(1.0, seed=1)


def test_heavy_clutter_tracks_the_targets_and_culls_tentative_tracks(heavy_clutter):
    """1 false alarm per frame and camera: both targets stay tracked within 3 m, every tentative track dies
    within confirm_within epochs (checked every step in ``run_clutter``) so the track list stays bounded."""
    run = heavy_clutter
    assert run["candidates"] > 150 and run["initiated"] > 20  # clutter did reach initiation, and started tracks
    assert max(run["errors"]) < 3.0
    assert run["most_tracks"] <= 30


@pytest.mark.xfail(strict=True, reason=(
    "known limitation: at 1 false alarm per frame ~200 clutter detections reach initiation in 30 s and ~50 pair into "
    "tentative tracks; some reach 3 hits in 8 steps, and clutter falling in a ghost's growing gate keeps it fresh: "
    "6-8 confirmed at the end (6-10 at most) in seeds 1-3, with one- or two-detection start-up alike. Needs a track "
    "score using the clutter density rather than M-of-N confirmation."))
def test_heavy_clutter_leaves_exactly_the_two_targets_confirmed(heavy_clutter):
    run = heavy_clutter
    assert len(run["tracker"].estimates()) == 2
    assert run["most_confirmed"] <= 4


# -- 3. initiation ---------------------------------------------------------------------------------------------


def initiation_nees(config: TrackerConfig, simulate_errors: bool, draws: int = 300, seed: int = 0) -> float:
    """Mean 3-D position NEES of tracks started from one bearing each (Monte Carlo over cameras, targets
    and noise). With ``simulate_errors`` the world has what the tracker's geolocation models: the ground is
    ``N(0, 2^2)`` m off the flat DEM and the reported camera position is ``N(0, 0.5^2 I)`` m off the truth."""
    config = dataclasses.replace(config, start_hits=1)  # a track from one bearing (a candidate holds the same point)
    rng = np.random.default_rng(seed)
    sensor = clean_sensor(seed + 1)
    nees = []
    for _ in range(draws):
        camera = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), ALTITUDE + rng.uniform(-5, 5)])
        radius = -ALTITUDE * np.tan(np.deg2rad(40.0)) * np.sqrt(rng.random())
        azimuth = rng.uniform(-np.pi, np.pi)
        ground_error = rng.normal(0.0, 2.0) if simulate_errors else 0.0
        target = camera + np.array([radius * np.cos(azimuth), radius * np.sin(azimuth), 0.0])
        target[2] = -ground_error  # heights are positive up
        (bearing,) = sensor.detect(1.0, camera, [{"id": "T", "position": target}])
        if simulate_errors:
            bearing = dataclasses.replace(bearing, sensor=camera + rng.normal(0.0, 0.5, 3))
        tracker = Tracker(config, STEP, GROUND)
        tracker.advance(5)  # t = 1.0 s
        assert tracker.update([bearing]) == {"updated": 0, "initiated": 1, "unused": 0}
        (track,) = tracker.tracks.values()
        assert not track.confirmed and track.hits == 1 and track.last_measured == 1.0
        est = track.estimate()  # newest-state marginal; the velocity block is the prior's, so use positions only
        d = est.mean[:3] - target
        nees.append(float(d @ np.linalg.solve(est.cov[:3, :3], d)))
    return float(np.mean(nees))


def test_initiation_covariance_is_honest():
    """With the errors it models present, the mean NEES of 300 one-bearing initiations lies in the two-sided
    99 % chi-square(3) interval. Without them it must not be overconfident either (it is conservative: the
    error then lies in the 2-D plane of the bearing noise). And the check has teeth: a geolocation that
    ignores the DEM and camera errors is flagged."""
    draws = 300
    low, high = stats.chi2.ppf([0.005, 0.995], 3 * draws) / draws
    assert low < initiation_nees(TrackerConfig(), simulate_errors=True, draws=draws) < high
    assert initiation_nees(TrackerConfig(), simulate_errors=False, draws=draws) < high
    blind = TrackerConfig(terrain_sigma=1e-3, sensor_sigma=1e-3)
    assert initiation_nees(blind, simulate_errors=True, draws=100) > high


# -- 4. track-to-track -----------------------------------------------------------------------------------------

SHARED = static("T1", 5.0, 5.0)  # seen by both agents
B_ONLY = static("T2", 70.0, 45.0)  # 100 m from A's camera: outside its 45 degree cone
CAMERA_A = np.array([-30.0, 0.0, ALTITUDE])
CAMERA_B = np.array([40.0, 20.0, ALTITUDE])


def measure_both(link: Link, sensors: dict, k: int, targets) -> None:
    t = k * STEP
    truth = [target(t) for target in targets]
    for name, camera in (("A", CAMERA_A), ("B", CAMERA_B)):
        link.trackers[name].advance(k)
        link.trackers[name].update(sensors[name].detect(t, camera, truth))


def test_peer_tracks_are_matched_through_the_label_table_or_adopted():
    config = TrackerConfig(policy="exact")
    link = Link(Tracker(config, STEP, GROUND), Tracker(config, STEP, GROUND))
    a, b = link.trackers["A"], link.trackers["B"]
    sensors = {"A": clean_sensor(11), "B": clean_sensor(12)}
    for k in range(10):
        measure_both(link, sensors, k, [SHARED, B_ONLY])
    assert len(a.estimates()) == 1 and len(b.estimates()) == 2
    a_t1, _ = nearest(a, SHARED(0)["position"])
    b_t1, _ = nearest(b, SHARED(0)["position"])
    b_t2, _ = nearest(b, B_ONLY(0)["position"])

    link.exchange()
    # A: B's T1 matched the local track (not duplicated); B's T2 matched nothing and was adopted, confirmed.
    assert len(a.tracks) == 2 and a_t1 in a.tracks
    (a_t2,) = set(a.tracks) - {a_t1}
    assert a.labels == {("B", b_t1): a_t1, ("B", b_t2): a_t2}
    assert a.tracks[a_t2].confirmed
    assert np.linalg.norm(a.tracks[a_t2].estimate().mean[:3] - B_ONLY(0)["position"]) < 3.0
    assert b.labels == {("A", a_t1): b_t1}
    assert len(b.tracks) == 2

    for k in range(10, 30):  # repeated messages go through the table: same pairs, one fusion per message
        measure_both(link, sensors, k, [SHARED, B_ONLY])
        link.exchange()
        assert a.labels == {("B", b_t1): a_t1, ("B", b_t2): a_t2}
        assert b.labels == {("A", a_t1): b_t1, ("A", a_t2): b_t2}
    assert set(a.tracks) == {a_t1, a_t2} and set(b.tracks) == {b_t1, b_t2}
    assert a.tracks[a_t1].fusions == {"exact": 21}
    assert a.tracks[a_t2].fusions == {"exact": 21}
    for target, track in ((SHARED, a_t1), (B_ONLY, a_t2)):
        assert np.linalg.norm(a.tracks[track].estimate().mean[:3] - target(0)["position"]) < 2.0


# -- 5. staleness ----------------------------------------------------------------------------------------------


def test_unmeasured_track_is_deleted_after_stale_after_whatever_peers_echo():
    """A and B track T1 for 2 s. Then only B measures, for 8 s (more than ``stale_after``): A's copy stays
    alive on B's measurements. Then nobody measures: B never advances again (so never deletes its copy) but
    keeps sending it, with its old ``last_measured``. A still deletes the track once ``stale_after`` has
    passed since the last measurement, and each copy B sends afterwards is adopted only until A's next step."""
    config = TrackerConfig(policy="exact")
    link = Link(Tracker(config, STEP, GROUND), Tracker(config, STEP, GROUND))
    a, b = link.trackers["A"], link.trackers["B"]
    sensors = {"A": clean_sensor(21), "B": clean_sensor(22)}
    for k in range(10):
        measure_both(link, sensors, k, [SHARED])
        link.exchange()
    (a_id,) = a.tracks
    # Only B measures for 8 s more (longer than stale_after): A's copy lives on B's measurements.
    for k in range(10, 50):
        a.advance(k)
        b.advance(k)
        b.update(sensors["B"].detect(k * STEP, CAMERA_B, [SHARED(k * STEP)]))
        link.exchange()
        assert a_id in a.tracks
    last = a.tracks[a_id].last_measured
    assert last == pytest.approx(49 * STEP)

    deadline = last + config.stale_after
    boundary = int(round(deadline / STEP))  # t = deadline exactly: "more than stale_after" is a float tie
    for k in range(50, boundary):  # nobody measures; B is frozen (never advances) and keeps echoing
        a.advance(k)
        link.exchange()
        assert a_id in a.tracks and a.tracks[a_id].last_measured == last
    a.advance(boundary)
    link.exchange()
    for k in range(boundary + 1, boundary + 4):
        a.advance(k)
        assert a.tracks == {} and a.labels == {}
        link.exchange()  # B's stale copy is adopted again, and dies at A's next step
        assert len(a.tracks) == 1 and a.labels == {("B", next(iter(b.tracks))): next(iter(a.tracks))}


# -- 6. duplicates ---------------------------------------------------------------------------------------------


def test_duplicate_tracks_are_merged_and_labels_move_to_the_kept_track():
    """B holds two confirmed tracks of one target (made with label-driven updates, as if two detectors gave it
    different names). A, tracking the target itself, receives both: the first matches A's track, the second
    cannot (that local track is claimed by the first), so it is adopted — and then merged into A's track, with
    its label moved there and the channel to B desynchronised (common information no longer known)."""
    config = TrackerConfig(policy="exact")
    a, b = Tracker(config, STEP, GROUND), Tracker(config, STEP, GROUND)
    sensor_a, sensor_b1, sensor_b2 = clean_sensor(31), clean_sensor(32), clean_sensor(33)
    cameras_b = (np.array([40.0, 20.0, ALTITUDE]), np.array([10.0, 50.0, ALTITUDE]))
    for k in range(10):
        t = k * STEP
        truth = [SHARED(t)]
        a.advance(k)
        b.advance(k)
        a.update(sensor_a.detect(t, CAMERA_A, truth))
        (x,) = sensor_b1.detect(t, cameras_b[0], truth)
        (y,) = sensor_b2.detect(t, cameras_b[1], truth)
        b.update([dataclasses.replace(x, truth_id="X"), dataclasses.replace(y, truth_id="Y")], by_label=True)
    (a_id,) = a.tracks
    assert len(b.estimates()) == 2
    b_x, b_y = sorted(b.tracks)

    broadcast(a, 1)  # A's message 1, which B never hears
    results = a.fuse_remote("B", received(broadcast(b, 1), "A"), 1)
    assert [r.method for r in results] == ["exact", "exact"]
    assert set(a.tracks) == {a_id}
    assert a.labels == {("B", b_x): a_id, ("B", b_y): a_id}
    kept = a.tracks[a_id]
    assert kept.last_measured == pytest.approx(9 * STEP)
    assert not kept.channels.is_synchronized("B")
    assert np.linalg.norm(kept.estimate().mean[:3] - SHARED(0)["position"]) < 2.0

    # Both labels lead to the kept track, whose channel to B is one filter: the first of B's copies is fused
    # (by intersection), the second arrives on the same channel with the same sequence number and is ignored.
    results = a.fuse_remote("B", received(broadcast(b, 2), "A"), 2)
    assert [r.method for r in results] == ["ci", "stale"]
    assert set(a.tracks) == {a_id} and kept.fusions == {"exact": 1, "ci": 1, "stale": 1}

    assert b.merge_duplicates() == 1  # B's own pair merges into the older track
    assert set(b.tracks) == {b_x}


def test_a_lost_track_is_continued_by_the_new_track_of_its_target():
    """A confirmed track coasts 3 s without detections while its target moves 3.7 sigma away (a manoeuvre its
    motion model does not cover); the target's next detections fall outside its bearing gate and start a new
    track, which passes the track-to-track gate with the lost one when it is confirmed. Nobody measured the
    lost one since the new one started: the new one continues it (in the 7-agent ring run of the default
    scenario, seed 1, dropping the new one instead left the car's track 20-27 m off for a second)."""
    tracker = Tracker(TrackerConfig(speed_std=2.0), STEP, GROUND)
    sensor, camera = clean_sensor(52), np.array([0.0, 0.0, ALTITUDE])
    start = static("T", 10.0, 0.0)
    for k in range(10):
        tracker.advance(k)
        tracker.update(sensor.detect(k * STEP, camera, [start(k * STEP)]))
    (lost_id,) = [tid for tid, _ in tracker.estimates()]
    tracker.advance(25)  # 3 s without a detection
    coasting = tracker.tracks[lost_id].estimate()
    sigma = float(np.sqrt(coasting.cov[0, 0]))  # north
    assert sigma > 4.0  # broad enough for the gates below to mean what they say
    moved = static("T", coasting.mean[0] + 3.7 * sigma, coasting.mean[1])
    for k in range(25, 25 + TrackerConfig().confirm_hits + 1):
        tracker.advance(k)
        tracker.update(sensor.detect(k * STEP, camera, [moved(k * STEP)]))
    (kept_id,) = [tid for tid, _ in tracker.estimates()]
    assert kept_id != lost_id and lost_id not in tracker.tracks
    assert nearest(tracker, moved(0)["position"])[1] < 3.0


def test_distinct_targets_are_not_merged():
    tracker = Tracker(TrackerConfig(), STEP, GROUND)
    sensor = clean_sensor(41)
    camera = np.array([0.0, 0.0, ALTITUDE])
    targets = [static("T1", -15.0, 10.0), static("T2", 20.0, -12.0)]
    for k in range(10):
        tracker.advance(k)
        tracker.update(sensor.detect(k * STEP, camera, [target(k * STEP) for target in targets]))
    assert len(tracker.estimates()) == 2
    assert tracker.merge_duplicates() == 0
    assert len(tracker.estimates()) == 2


# -- 7. exact fusion on a tree ---------------------------------------------------------------------------------


GATE_ALL = 50.0  # one target, no clutter: the ~1 % of bearings beyond d^2 = 9 must not start second tracks here


def moving_target(t: float) -> list[dict]:
    return [{"id": "T", "position": np.array([-5.0, 0.0, 0.0]) + t * np.array([2.0, 1.0, 0.0])}]


def run_pair(config: TrackerConfig, steps: int = 40):
    """A alone initiates and confirms the target (steps 0-2; ``config.start_hits = 1``), B adopts A's track from
    A's first message and only then measures too; both exchange every step. Yields, after every step's exchange, the
    phase ("alone", "adopted" or "both"), the trackers, the step and the bearings A and B applied."""
    link = Link(Tracker(config, STEP, GROUND), Tracker(config, STEP, GROUND))
    a, b = link.trackers["A"], link.trackers["B"]
    sensor_a, sensor_b = clean_sensor(51), clean_sensor(52)
    camera_b = np.array([25.0, 20.0, ALTITUDE])
    for k in range(steps):
        t = k * STEP
        a.advance(k)
        b.advance(k)
        from_a = sensor_a.detect(t, CAMERA_A, moving_target(t))
        from_b = sensor_b.detect(t, camera_b, moving_target(t))
        assert len(from_a) == 1 and len(from_b) == 1
        b_measures = bool(b.tracks)
        expected = "updated" if a.tracks else "initiated"
        assert a.update(from_a)[expected] == 1
        if b_measures:
            assert b.update(from_b)["updated"] == 1
        else:
            from_b = []
        link.exchange()
        assert len(a.tracks) == 1 and len(b.tracks) <= 1
        phase = "both" if b_measures else ("adopted" if b.tracks else "alone")
        yield phase, a, b, k, from_a, from_b


@pytest.mark.parametrize("measurement", ["bearing", "position"])
def test_exact_fusion_on_a_tree_equals_the_centralized_filter(measurement):
    """Policy ``exact``, two agents on one link, messages every step with acknowledgements.

    The velocity prior is common information (``DampedVelocity``: it is in every trajectory prior) and only A
    initiates, so the only information in the system is A's geolocated first bearing plus every later
    bearing, each counted once. After each exchange A and B hold the same belief, and it equals:

    * ``measurement="position"`` (linear updates): a centralized Tracker that applied all the bearings;
    * ``measurement="bearing"`` (EIF): the centralized multi-sensor EIF update of Merino (3.34)-(3.35), in
      which every bearing of a step is linearized at the common predicted mean — exactly what each agent
      does locally. A centralized *Tracker* applies them one after the other, relinearizing the second at the
      mean after the first, so it differs at second order (checked here to a fifth of a standard deviation)."""
    config = TrackerConfig(policy="exact", measurement=measurement, gate=GATE_ALL, start_hits=1)
    central = Tracker(config, STEP, GROUND)
    reference = None
    checked = 0
    for phase, a, b, k, from_a, from_b in run_pair(config):
        central.advance(k)
        for bearings in (from_a, from_b):
            if bearings:
                central.update(bearings)
        (track_a,) = a.tracks.values()
        (track_c,) = central.tracks.values()
        if phase == "alone":
            continue
        (track_b,) = b.tracks.values()
        if phase == "adopted":  # B's track is A's message, which is what the centralized filter has
            assert track_b.belief.allclose(track_a.belief, rtol=1e-12, atol=1e-12)
            assert track_a.belief.allclose(track_c.belief, rtol=1e-12, atol=1e-12)
            reference = track_a.belief
            continue
        reference = reference.advanced_to(k)
        if measurement == "bearing":
            predicted = reference.current().mean
            for bearing in from_a + from_b:
                model = Bearing3D(STATE_DIM, bearing.sensor, bearing.R)
                reference = reference.eif_update(model, bearing.azel, 0, linearization_point=predicted)
        else:
            reference = track_c.belief
        assert set(track_a.fusions) == {"exact"} and set(track_b.fusions) == {"exact"}
        for track in (track_a, track_b):
            assert relative(track.belief.Y, reference.Y) < 1e-6
            assert relative(track.belief.y, reference.y) < 1e-6
            mine, ref = track.estimate(), reference.current()
            assert relative(mine.Y, ref.Y) < 1e-6  # the newest-state marginal, not only the whole window
            assert np.allclose(mine.mean, ref.mean, rtol=0, atol=1e-6)
        gap = np.linalg.norm(track_a.estimate().mean[:3] - track_c.estimate().mean[:3])
        assert gap < 0.2 * np.sqrt(np.linalg.eigvalsh(track_c.estimate().cov[:3, :3]).min())
        checked += 1
    assert checked > 30


def test_naive_fusion_on_the_same_run_is_not_centralized():
    """The comparison above has teeth: treating every message as independent evidence double-counts, and
    the fused newest-state information ends far above the centralized one."""
    config = TrackerConfig(policy="naive", measurement="position", gate=GATE_ALL, start_hits=1)
    central = Tracker(config, STEP, GROUND)
    steps = list(run_pair(config, steps=20))
    for _phase, _a, _b, k, from_a, from_b in steps:
        central.advance(k)
        for bearings in (from_a, from_b):
            if bearings:
                central.update(bearings)
    ((_, fused),) = steps[-1][1].estimates()
    ((_, centralized),) = central.estimates()
    assert np.linalg.eigvalsh(fused.Y[:3, :3]).max() > 2.0 * np.linalg.eigvalsh(centralized.Y[:3, :3]).max()


def test_merge_skips_a_track_that_is_not_fully_observable():
    """Bad state (found by the rumor benchmark under exact fusion on loops): a confirmed track whose belief
    is singular must be skipped by duplicate merging, not crash the agent."""
    from fusion.trajectory import Trajectory
    from perception.terrain import FlatTerrain

    tracker = Tracker(TrackerConfig(), 0.2, FlatTerrain())
    for _ in range(2):
        track = tracker._new_track(Trajectory.prior(tracker.model, 0))  # the prior: no position information
        track.confirmed = True
    assert tracker.merge_duplicates() == 0
    assert len(tracker.tracks) == 2


def test_a_track_whose_newest_state_is_not_fully_observable_is_not_an_estimate():
    """Measured in ``bench rumor`` (7 agents, tree, 30 % loss, hybrid): two agents crashed in their telemetry on
    a confirmed track whose newest-state information matrix was singular (the marginal existed, its covariance
    did not). Such a track is left out of the estimates (telemetry, views and scoring read only those)."""
    tracker = Tracker(TrackerConfig(), STEP, GROUND)
    n, L = STATE_DIM, tracker.model.window
    Y = np.eye(n * L)
    Y[-1, -1] = 0.0  # the newest state's vertical velocity: no information at all
    track = tracker._new_track(Trajectory(np.zeros(n * L), Y, 0, tracker.model))
    track.confirmed = True
    with pytest.raises(UninformativeBeliefError):
        track.estimate().cov  # noqa: B018
    assert tracker.estimates() == []


def test_a_steps_scans_applied_together_equal_one_update_per_scan(monkeypatch):
    """``update_scans`` (what flood applies once per step) against one ``update`` per scan in the same epoch:
    every detection of an epoch is gated and linearised at the epoch's prediction (Merino (3.52)), so holding
    a step's bearings and adding them at once gives the same tracks; and each track's window marginal is
    computed once per offset and step, not after every scan."""
    from fusion import trajectory

    marginals = []
    original = trajectory.Trajectory._marginal
    monkeypatch.setattr(trajectory.Trajectory, "_marginal", lambda self, k: marginals.append(k) or original(self, k))
    sensors = [clean_sensor(7 + i) for i in range(len(CROSSING_CAMERAS))]
    one_by_one, together = Tracker(TrackerConfig(), STEP, GROUND), Tracker(TrackerConfig(), STEP, GROUND)
    checked = 0
    for k in range(40):
        t = k * STEP
        truth = crossing(t)
        scans = [sensor.detect(t, camera, truth) for sensor, camera in zip(sensors, CROSSING_CAMERAS, strict=True)]
        late = [[dataclasses.replace(b, t=t - STEP) for b in scans[0]]] if k else []  # a peer's, one step late
        one_by_one.advance(k)
        for scan in scans + late:
            one_by_one.update(scan)
        together.advance(k)
        tracks = len(together.tracks)
        marginals.clear()
        together.update_scans(scans + late)
        if k > 10 and len(together.tracks) == tracks:  # no track started: every marginal asked is a prediction
            assert len(marginals) <= 2 * tracks  # offsets 0 and 1 (one update per scan would ask ~5 per track)
            checked += 1
    assert checked >= 20
    got, expected = together.estimates(), one_by_one.estimates()
    assert len(got) == len(expected) == 2
    for (_, g), (_, e) in zip(got, expected, strict=True):
        np.testing.assert_allclose(g.mean, e.mean, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(g.cov, e.cov, rtol=1e-9, atol=1e-12)


def test_a_track_too_uncertain_is_deleted_exactly_when_its_largest_position_std_passes_the_limit():
    """Oracle: the eigenvalues of the position covariance (numpy). Tracks started from position measurements of
    random orientation and size, their largest standard deviation within ±10 % of ``max_position_std`` after the
    prediction: the tracker deletes exactly those beyond it."""
    config = TrackerConfig(max_position_std=40.0, confirm_within=100, stale_after=1e9)
    rng = np.random.default_rng(5)
    outcomes = set()
    for _ in range(40):
        tracker = Tracker(config, 0.2, FlatTerrain(0.0))
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        cov = Q @ np.diag([rng.uniform(1, 30) ** 2, rng.uniform(1, 30) ** 2, (40.0 * rng.uniform(0.9, 1.1)) ** 2]) @ Q.T
        track = tracker._start_track(np.zeros(3), cov, 0, None, 0.0)
        std = float(np.sqrt(np.linalg.eigvalsh(track.estimate().cov[:3, :3]).max()))
        if abs(std - 40.0) < 1e-6:
            continue
        outcomes.add(std > 40.0)
        assert tracker._too_uncertain(track) == (std > 40.0), std
    assert outcomes == {True, False}  # both sides of the limit were tried
