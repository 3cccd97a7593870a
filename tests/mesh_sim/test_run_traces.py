"""The world's record of a run for its map and link plots: one row a second, every neighbour change."""

from __future__ import annotations

import numpy as np

from mesh_sim.run_traces import RunTraces


def test_positions_once_a_second_and_every_neighbour_change():
    traces = RunTraces()
    for k in range(25):  # 2.5 s of telemetry at 10 Hz
        t = 0.1 * k
        peers = ["uav1"] if t < 1.25 else []
        traces.on_telemetry("uav0", t, {"position": np.array([t, 2 * t, -50.0]), "neighbours": [*peers, "uav0"],
                                        "tracks": [{"id": 3, "mean": np.array([5.0, 6.0, 0, 0, 0, 0])}]})
        traces.on_truth(t, [{"id": "car", "position": [t, 0.0, 0.0]}])
    out = traces.summary()
    assert [row[0] for row in out["uavs"]["uav0"]] == [0.0, 1.0, 2.0]
    assert out["tracks"]["uav0"][0] == [0.0, "3", 5.0, 6.0]
    assert [row[0] for row in out["truth"]["car"]] == [0.0, 1.0, 2.0]
    assert out["neighbours"]["uav0"] == [[0.0, ["uav1"]], [0.1 * 13, []]]  # the agent itself is left out
