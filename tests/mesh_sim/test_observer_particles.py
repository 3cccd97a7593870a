"""The ground station draws track candidates' particles as points, and rejects malformed particle arrays."""

from __future__ import annotations

import uuid

import numpy as np

from agent.net.keys import Incoming, Keys
from mesh_sim.observer import Observer
from tests.mesh_sim.test_observer import _envelope, _read_rrd, _telemetry


def test_particles_in_telemetry_are_logged_as_points(tmp_path):
    keys = Keys(f"t{uuid.uuid4().hex[:12]}")
    obs = Observer(keys, recording_id=f"rec-{uuid.uuid4().hex[:8]}")
    obs.save(tmp_path / "obs.rrd")
    cloud = np.random.default_rng(0).normal(size=(64, 3)).astype(np.float32)
    good = _telemetry("uav0", 1, 0.2, [], particles=cloud)
    assert obs.handle(Incoming(keys.telemetry("uav0"), _envelope("telemetry", "uav0", 1, 0.2, good), 0.0))
    for seq, bad in ((2, np.zeros((5, 2), np.float32)), (3, np.full((4, 3), np.nan))):  # wrong shape; NaN
        payload = _telemetry("uav0", seq, 0.4, [], particles=bad)
        assert not obs.handle(Incoming(keys.telemetry("uav0"), _envelope("telemetry", "uav0", seq, 0.4, payload), 0.0))
    assert obs.rejected == {"bad_shape": 1, "non_finite": 1}
    obs.close()
    rows, last = _read_rrd(tmp_path / "obs.rrd")
    assert rows.get("/world/agents/uav0/particles", 0) == 1
    assert len(last["/world/agents/uav0/particles"].column("Points3D:positions").to_pylist()[-1]) == 64
