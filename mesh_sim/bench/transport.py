"""``skymesh bench transport``: per-hop latency and throughput of the agent transport vs bare Zenoh.

Set-up (the deployment of ``skymesh run`` on one machine): this process opens a Zenoh router on a free
loopback port (``agent.net.zenoh_transport.router_config``) and starts ONE echo process (``python -m
mesh_sim.bench.transport --echo ...``, a hidden mode of this module) that connects to it as a client.
The pinging side is a client session of this process too, so every message travels client -> router
-> client, exactly one agent-to-agent hop; a round trip is two hops (one-way = RTT / 2).

Three paths, measured in the same run and interleaved block by block (``repeats`` blocks, so that
drifts of the machine hit all alike); the ratios agent / bare are the result:

* **bare**: ``session.declare_publisher`` and a subscriber callback, raw bytes of the size of one
  encoded trajectory track (~4.9 kB). The echo's callback takes the payload as bytes and puts it back
  on the pong key; the pinger's callback checks the sequence number and sets a ``threading.Event``
  that the main thread waits on (the fastest way to wait in Python; ``dependencies.md`` §2.8).
* **agent**: :class:`agent.net.zenoh_transport.ZenohTransport` (``publish`` + ``drain()``, the agent's bounded
  queue filled by Zenoh's callback thread), busy-polled with a ``POLL_SLEEP_S`` sleep when the queue is
  empty (the agent drains once per step; polling is what it would take to react at once), and the wire
  format: a ``track`` :class:`agent.net.wire.Envelope` carrying one real trajectory belief
  (``TrajectoryModel(ConstantVelocity(3, 3.0), 0.2, 8)``, ``gaussian_codec.encode_trajectory``). Each side
  encodes (``encode_trajectory`` + ``wire.encode``) what it sends and decodes and validates
  (``wire.decode`` + ``decode_trajectory``: shapes, finiteness, symmetric PSD information matrix) what
  it receives, as an agent does; the echo acknowledges the ping's sequence number in ``acks``.
* **queue** (to split the difference): the agent path without the wire format — ``ZenohTransport``
  publish + ``drain()`` polling of the bare path's raw bytes.

Measurements:

* **round trip**: ``round_trips`` ping-pongs per path after a warm-up; median, p90, p99 and mean in µs
  (a reply not back within ``RTT_TIMEOUT_S`` counts as lost);
* **throughput**: bursts of ``burst`` messages sent back to back (default congestion control, DROP, as
  the transport uses); the echo counts what it receives (and, on the agent path, decodes) and reports;
  delivered messages per second = delivered / (last arrival - first send), median over the bursts;
* **codec**: the encode and decode+validate costs of one message in this process (no network, a hot
  loop), and the ping side's encode + decode measured inside the agent round trips (after each wait,
  with cold caches: about twice the hot-loop figure): agent RTT ~ queue RTT + 2 x (encode + decode).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import queue
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from mesh_sim.bench import common

NAME = "transport"
QUICK_ROUND_TRIPS, FULL_ROUND_TRIPS = 2000, 20000  # per path (from the issue)
DECODE_SPEEDUP_GOAL = 20.0  # issue 12: a track message decoded >= 20x faster than the v1 decoder
HOP_GOAL = 2.0  # issue 12: agent RTT <= 2x bare Zenoh
QUICK_BURST, FULL_BURST = 2000, 8000  # messages per throughput burst; below the transport's queue limit (chosen here)
QUICK_BLOCKS, FULL_BLOCKS = 3, 5  # interleaved blocks (round trips, then a burst, of every path); chosen here
PATHS = ("bare", "queue", "agent")
WARMUP_ROUND_TRIPS = 200  # per path, before the first block (chosen here)
POLL_SLEEP_S = 20e-6  # sleep of the busy-poll when the transport's queue is empty, both ends (chosen here)
RTT_TIMEOUT_S = 2.0  # a reply later than this counts as lost (chosen here)
ECHO_START_TIMEOUT_S = 30.0
REPORT_SETTLE_S = 0.5  # a burst is over when the echo's count has not moved for this long (chosen here)
BURST_TIMEOUT_S = 60.0
SEED = 7

# the track carried by the agent path: a 6-state constant-velocity trajectory over 8 states of 0.2 s
MOTION_Q, STEP_S, WINDOW = 3.0, 0.2, 8


def _model():
    from fusion.motion import ConstantVelocity
    from fusion.trajectory import TrajectoryModel

    return TrajectoryModel(ConstantVelocity(3, MOTION_Q), STEP_S, WINDOW)


def make_track(model=None, rng: np.random.Generator | None = None):
    """A realistic track: 2 windows of noisy position fixes of a target moving at constant velocity."""
    from fusion.trajectory import Trajectory

    model = model or _model()
    rng = rng or np.random.default_rng(SEED)
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    R_inv = np.eye(3) / 4.0  # 2 m standard deviation
    traj = Trajectory.prior(model, 0)
    for k in range(1, 2 * model.window + 1):
        truth = np.array([10.0 + 1.5 * k * model.step, -20.0 + 0.5 * k * model.step, 0.0])
        traj = traj.advanced_to(k).update(H, R_inv, truth + rng.normal(0.0, 2.0, 3))
    return traj


@dataclass
class Codec:
    """Encode / decode one ``track`` message the way an agent does."""

    origin: str
    peer: str
    model: object

    def encode(self, traj, seq: int, stamp: float, acked: int | None) -> bytes:
        from agent.net import gaussian_codec, wire

        payload = {"tracks": [{"id": 1, "belief": gaussian_codec.encode_trajectory(traj), "last_measured": stamp}]}
        acks = {} if acked is None else {self.peer: acked}
        return wire.encode(wire.Envelope(kind="track", origin=self.origin, seq=seq, stamp=stamp, acks=acks,
                                         payload=payload))

    def decode(self, data: bytes, wire_decode=None):
        """Returns ``(envelope, trajectory)``; raises ``wire.DecodeError`` on anything invalid. ``wire_decode``
        replaces :func:`agent.net.wire.decode` (the v1 baseline)."""
        from agent.net import gaussian_codec, wire

        env = (wire_decode or wire.decode)(data, expected_origin=self.peer)
        tracks = env.payload.get("tracks")
        if not isinstance(tracks, list) or len(tracks) != 1 or not isinstance(tracks[0], dict):
            raise wire.DecodeError("bad_field", "expected one track")
        return env, gaussian_codec.decode_trajectory(tracks[0].get("belief"), self.model)


class _Keys:
    def __init__(self, fleet: str):
        from agent.net.keys import Keys

        root = Keys(fleet).root
        self.bare_ping, self.bare_pong = f"{root}/bench/bare/ping", f"{root}/bench/bare/pong"
        self.queue_ping, self.queue_pong = f"{root}/bench/transport/ping", f"{root}/bench/transport/pong"
        self.ctl, self.ctl_reply = f"{root}/bench/ctl", f"{root}/bench/ctl_reply"


# ==================================================================================================
# the benchmark (pinging side)
# ==================================================================================================
def run(
    quick: bool = False,
    repeats: int | None = None,
    *,
    round_trips: int | None = None,
    burst: int | None = None,
    poll_sleep: float = POLL_SLEEP_S,
) -> dict:
    """Run the benchmark. ``repeats``: interleaved blocks (default 3 quick, 5 full); ``round_trips``:
    ping-pongs per path in total (default 2000 / 20000); ``burst``: messages per throughput burst;
    ``poll_sleep``: seconds slept by the queue and agent paths' busy-polls when there is nothing."""
    blocks = repeats if repeats is not None else QUICK_BLOCKS if quick else FULL_BLOCKS
    round_trips = round_trips if round_trips is not None else QUICK_ROUND_TRIPS if quick else FULL_ROUND_TRIPS
    burst = burst if burst is not None else QUICK_BURST if quick else FULL_BURST
    for name, value in (("repeats", blocks), ("round_trips", round_trips), ("burst", burst)):
        if int(value) != value or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value}")
    if not 0 <= poll_sleep < 0.1:
        raise ValueError(f"poll_sleep must be in [0, 0.1) s, got {poll_sleep}")
    per_block = [round_trips // blocks + (b < round_trips % blocks) for b in range(blocks)]
    warmup = min(WARMUP_ROUND_TRIPS, max(20, round_trips // 10))
    load_before = os.getloadavg()
    samples: dict[str, list[float]] = {p: [] for p in PATHS}
    lost = dict.fromkeys(PATHS, 0)
    bursts: dict[str, list[dict]] = {p: [] for p in PATHS}
    with _Bench(poll_sleep) as bench:
        plan = ["warm-up"] + [f"block {b + 1}/{blocks}" for b in range(blocks)]
        with common.progress(len(plan), NAME) as advance:
            for b, label in enumerate(plan, start=-1):
                advance(label)
                for path in PATHS:
                    if b < 0:
                        bench.round_trips(path, warmup)
                        bench.codec_in_loop_us.clear()
                        continue
                    rtts, missing = bench.round_trips(path, per_block[b]) if per_block[b] else ([], 0)
                    samples[path].extend(rtts)
                    lost[path] += missing
                if b >= 0:
                    for path in PATHS:
                        bursts[path].append(bench.burst(path, burst))
        size = {"bare": len(bench.bare_payload), "queue": len(bench.bare_payload), "agent": len(bench.agent_sample)}
        echo_pid = bench.echo.pid
        in_loop = list(bench.codec_in_loop_us)
    codec = _time_codec(quick)
    codec["ping_side_in_round_trips"] = float(np.median(in_loop)) if in_loop else math.nan
    rows = [_row(path, samples[path], lost[path], bursts[path], size[path]) for path in PATHS]
    by_path = {r["path"]: r for r in rows}
    ratios = _ratios(by_path["agent"], by_path["bare"])
    return {
        "benchmark": NAME,
        "settings": {
            "quick": quick, "blocks": blocks, "round_trips_per_path": round_trips, "warmup": warmup,
            "burst": burst, "poll_sleep_s": poll_sleep, "rtt_timeout_s": RTT_TIMEOUT_S, "seed": SEED,
            "track_model": {"motion": f"ConstantVelocity(3, {MOTION_Q})", "step_s": STEP_S, "window": WINDOW},
            "echo_pid": echo_pid, "load_average_before": list(load_before), "load_average_after": list(os.getloadavg()),
        },
        "environment": common.environment(("numpy", "eclipse-zenoh", "msgspec")),
        "rows": rows,
        "codec": codec,
        "ratios": ratios,
        "ratios_queue_over_bare": _ratios(by_path["queue"], by_path["bare"]),
        "ratios_agent_over_queue": _ratios(by_path["agent"], by_path["queue"]),
        "goals": {
            "description": "issue 12: decoding a track message >= 20x faster than the v1 decoder, the agent hop "
                           "(RTT) <= 2x bare Zenoh; same run, same machine",
            "agent_over_bare": ratios,
            "decode_speedup": codec["decode_speedup"],
            "decode_speedup_pass": codec["decode_speedup"] >= DECODE_SPEEDUP_GOAL,
            "hop_pass": ratios["rtt_median"] <= HOP_GOAL,
        },
    }


def _ratios(row: dict, base: dict) -> dict:
    return {
        "rtt_median": row["rtt_median_us"] / base["rtt_median_us"],
        "rtt_p90": row["rtt_p90_us"] / base["rtt_p90_us"],
        "rtt_p99": row["rtt_p99_us"] / base["rtt_p99_us"],
        "rtt_mean": row["rtt_mean_us"] / base["rtt_mean_us"],
        "throughput": row["throughput_msgs_s"] / base["throughput_msgs_s"],
    }


def _row(path: str, rtts: list[float], lost: int, bursts: list[dict], size: int) -> dict:
    us = np.asarray(rtts, float) * 1e6
    pct = (lambda q: float(np.percentile(us, q))) if us.size else (lambda q: math.nan)
    rates = [b["delivered"] / b["span_s"] for b in bursts if b["span_s"] > 0 and b["delivered"]]
    send = [b["sent"] / b["send_s"] for b in bursts if b["send_s"] > 0]
    delivered = sum(b["delivered"] for b in bursts)
    sent = sum(b["sent"] for b in bursts)
    throughput = float(np.median(rates)) if rates else math.nan
    return {
        "path": path, "message_bytes": size, "round_trips": int(us.size), "lost": lost,
        "rtt_median_us": pct(50), "rtt_p90_us": pct(90), "rtt_p99_us": pct(99),
        "rtt_mean_us": float(us.mean()) if us.size else math.nan,
        "rtt_min_us": float(us.min()) if us.size else math.nan,
        "one_way_median_us": pct(50) / 2,
        "throughput_msgs_s": throughput, "throughput_mb_s": throughput * size / 1e6,
        "throughput_bursts_msgs_s": rates, "send_rate_msgs_s": float(np.median(send)) if send else math.nan,
        "burst_sent": sent, "burst_delivered": delivered,
        "delivered_share": delivered / sent if sent else math.nan,
        "echo_queue_dropped": sum(b.get("dropped", 0) for b in bursts),
        "echo_rejected": sum(b.get("rejected", 0) for b in bursts),
    }


def _time_codec(quick: bool) -> dict:
    """µs per message of the agent path's encode and decode+validate, in this process, and the same decode with
    the v1 decoder (:mod:`mesh_sim.bench.legacy_wire`, today's baseline; same bytes, same belief codec) — for a
    ``track`` message and for a flood message (three detection batches and the acknowledgements of 40 agents,
    what an agent of a 40-agent fleet receives most)."""
    from agent.net import wire
    from mesh_sim.bench import legacy_wire

    model = _model()
    traj = make_track(model)
    sender, receiver = Codec("ping", "echo", model), Codec("echo", "ping", model)
    data = sender.encode(traj, 1, 3.2, 1)
    flood = wire.encode(wire.Envelope(kind="track", origin="uav1", seq=9, stamp=3.2, payload={
        "increments": [[f"uav{i}", 100 + i, np.random.default_rng(i).random((2, 9))] for i in range(3)],
        "acks": {f"uav{i}": [100 + i, 2**40 + i] for i in range(40)}}))

    timings = common.time_calls(
        {"encode": lambda: sender.encode(traj, 1, 3.2, 1), "decode": lambda: receiver.decode(data),
         "decode_v1": lambda: receiver.decode(data, legacy_wire.decode),
         "decode_flood": lambda: wire.decode(flood), "decode_flood_v1": lambda: legacy_wire.decode(flood)},
        common.Settings.create(quick),
    )
    out = {name: t.median_us for name, t in timings.items()}
    out["decode_speedup"] = out["decode_v1"] / out["decode"]
    out["decode_flood_speedup"] = out["decode_flood_v1"] / out["decode_flood"]
    return out


class _Bench:
    """The router, the client sessions of the pinging side and the echo process (killed by PID on exit)."""

    def __init__(self, poll_sleep: float = POLL_SLEEP_S):
        self.poll_sleep = poll_sleep

    def __enter__(self) -> _Bench:
        import zenoh

        from agent.net.keys import Keys
        from agent.net.zenoh_transport import ZenohTransport, client_config, router_config
        from mesh_sim.launcher import free_port

        zenoh.init_log_from_env_or("error")
        self.fleet = f"bench-{uuid.uuid4().hex[:12]}"
        self.keys = _Keys(self.fleet)
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.echo = None
        self._closers = []
        self._stderr = tempfile.TemporaryFile()
        try:
            self.router = zenoh.open(router_config([self.endpoint]))
            self._closers.append(self.router.close)
            self.session = zenoh.open(client_config([self.endpoint]))
            self._closers.insert(0, self.session.close)
            self.transport = ZenohTransport("ping", Keys(self.fleet), client_config([self.endpoint]),
                                            [self.keys.queue_pong], liveliness=False)
            self._closers.insert(0, self.transport.close)
            self._replies: queue.Queue = queue.Queue()
            self.session.declare_subscriber(self.keys.ctl_reply, lambda s: self._replies.put(s.payload.to_bytes()))
            self.ctl = self.session.declare_publisher(self.keys.ctl)
            self._ctl_id = 0
            # bare path
            self._expected = -1
            self._got = threading.Event()
            self.bare_pub = self.session.declare_publisher(self.keys.bare_ping)
            self.session.declare_subscriber(self.keys.bare_pong, self._on_bare_pong)
            # agent path
            self.model = _model()
            self.traj = make_track(self.model)
            self.codec = Codec("ping", "echo", self.model)
            self.seq = 0
            self.codec_in_loop_us: list[float] = []  # ping side's encode + decode per agent round trip
            self.agent_sample = self.codec.encode(self.traj, 1, 3.2, None)
            self.bare_payload = bytearray(os.urandom(len(self.agent_sample)))
            self._start_echo()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc) -> None:
        try:
            if self.echo is not None and self.echo.poll() is None:
                try:
                    self._request({"op": "quit"}, timeout=0.5, want_reply=False)
                    self.echo.wait(timeout=2.0)
                except Exception:  # the echo is killed below whatever went wrong
                    pass
        finally:
            if self.echo is not None and self.echo.poll() is None:
                self.echo.kill()  # by PID (Popen), never by name
            if self.echo is not None:
                self.echo.wait()
            for close in self._closers:
                try:
                    close()
                except Exception:  # closing must not mask the real error
                    pass
            self._stderr.close()

    # -- control of the echo ------------------------------------------------------------------------
    def _start_echo(self) -> None:
        cmd = [sys.executable, "-m", "mesh_sim.bench.transport", "--echo", "--connect", self.endpoint,
               "--fleet", self.fleet, "--parent", str(os.getpid()), "--poll-sleep", repr(self.poll_sleep)]
        self.echo = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=self._stderr)
        deadline = time.time() + ECHO_START_TIMEOUT_S
        while time.time() < deadline:
            if self.echo.poll() is not None:
                self._stderr.seek(0)
                raise RuntimeError(f"echo process exited with code {self.echo.returncode}: "
                                   f"{self._stderr.read().decode(errors='replace')[-2000:]}")
            try:
                self._request({"op": "hello"}, timeout=0.2)
                return
            except TimeoutError:
                continue
        raise RuntimeError(f"echo process did not answer within {ECHO_START_TIMEOUT_S:g} s")

    def _request(self, msg: dict, timeout: float = 10.0, want_reply: bool = True) -> dict | None:
        self._ctl_id += 1
        msg = {**msg, "id": self._ctl_id}
        self.ctl.put(json.dumps(msg).encode())
        if not want_reply:
            return None
        deadline = time.time() + timeout
        while (left := deadline - time.time()) > 0:
            try:
                reply = json.loads(self._replies.get(timeout=left))
            except queue.Empty:
                break
            if reply.get("id") == self._ctl_id:
                return reply
        raise TimeoutError(f"no reply from the echo process to {msg['op']!r}")

    def _mode(self, mode: str) -> None:
        self._request({"op": "mode", "mode": mode})

    # -- bare path ------------------------------------------------------------------------------------
    def _on_bare_pong(self, sample) -> None:
        data = sample.payload.to_bytes()
        if int.from_bytes(data[:8], "little") == self._expected:
            self._got.set()

    def round_trips(self, path: str, n: int) -> tuple[list[float], int]:
        """``n`` ping-pongs on ``path``: (round-trip times [s], replies lost)."""
        return {"bare": self._bare_round_trips, "queue": self._queue_round_trips,
                "agent": self._agent_round_trips}[path](n)

    def burst(self, path: str, n: int) -> dict:
        """``n`` messages back to back on ``path``, counted by the echo."""
        return {"bare": self._bare_burst, "queue": self._queue_burst, "agent": self._agent_burst}[path](n)

    def _next_bare(self) -> bytes:
        self.seq += 1
        self.bare_payload[:8] = self.seq.to_bytes(8, "little")
        return bytes(self.bare_payload)

    def _bare_round_trips(self, n: int) -> tuple[list[float], int]:
        self._mode("bare-echo")
        rtts, lost = [], 0
        pub, got, clock = self.bare_pub, self._got, time.perf_counter
        for _ in range(n):
            data = self._next_bare()
            got.clear()
            self._expected = self.seq
            start = clock()
            pub.put(data)
            if got.wait(RTT_TIMEOUT_S):
                rtts.append(clock() - start)
            else:
                lost += 1
        self._mode("idle")
        return rtts, lost

    def _bare_burst(self, n: int) -> dict:
        self._mode("bare-count")
        data, pub = bytes(self.bare_payload), self.bare_pub
        start = time.time()
        for _ in range(n):
            pub.put(data)
        return self._burst_result(n, start, time.time())

    def _drained_until_timeout(self, start: float) -> Iterator[list]:
        """Batches drained from the transport until RTT_TIMEOUT_S after ``start`` (perf_counter); the caller
        stops iterating once it has its reply."""
        while time.perf_counter() - start < RTT_TIMEOUT_S:
            items = self.transport.drain()
            if items:
                yield items
            else:
                time.sleep(self.poll_sleep)

    # -- queue path: ZenohTransport without the wire format ---------------------------------------------
    def _queue_round_trips(self, n: int) -> tuple[list[float], int]:
        self._mode("queue-echo")
        rtts, lost = [], 0
        transport, key, clock = self.transport, self.keys.queue_ping, time.perf_counter
        for _ in range(n):
            data = self._next_bare()
            expected = data[:8]
            start = clock()
            transport.publish(key, data)
            if any(item.data[:8] == expected for items in self._drained_until_timeout(start) for item in items):
                rtts.append(clock() - start)
            else:
                lost += 1
        self._mode("idle")
        transport.drain()
        return rtts, lost

    def _queue_burst(self, n: int) -> dict:
        self._mode("queue-count")
        transport, key = self.transport, self.keys.queue_ping
        data = self._next_bare()
        start = time.time()
        for _ in range(n):
            transport.publish(key, data)
        return self._burst_result(n, start, time.time())

    # -- agent path -----------------------------------------------------------------------------------
    def _agent_round_trips(self, n: int) -> tuple[list[float], int]:
        from agent.net import wire

        self._mode("agent-echo")
        rtts, lost = [], 0
        transport, codec, key, clock = self.transport, self.codec, self.keys.queue_ping, time.perf_counter
        acked = None
        for _ in range(n):
            self.seq += 1
            seq = self.seq
            start = clock()
            data = codec.encode(self.traj, seq, 3.2, acked)
            encode_s = clock() - start
            transport.publish(key, data)
            done = False
            for items in self._drained_until_timeout(start):
                for item in items:
                    decode_start = clock()
                    try:
                        env, _ = codec.decode(item.data)
                    except wire.DecodeError:
                        continue
                    acked = env.seq
                    if env.acks.get("ping") == seq:
                        done = True
                        self.codec_in_loop_us.append(1e6 * (encode_s + clock() - decode_start))
                if done:
                    break
            if done:
                rtts.append(clock() - start)
            else:
                lost += 1
        self._mode("idle")
        transport.drain()
        return rtts, lost

    def _agent_burst(self, n: int) -> dict:
        self._mode("agent-count")
        transport, codec, key = self.transport, self.codec, self.keys.queue_ping
        start = time.time()
        for _ in range(n):
            self.seq += 1
            transport.publish(key, codec.encode(self.traj, self.seq, 3.2, None))
        return self._burst_result(n, start, time.time())

    def _burst_result(self, sent: int, start: float, sent_at: float) -> dict:
        """Poll the echo's count until it reaches ``sent`` or stops moving."""
        last_count, moved_at = -1, time.time()
        while True:
            report = self._request({"op": "report"})
            now = time.time()
            if report["count"] != last_count:
                last_count, moved_at = report["count"], now
            if report["count"] >= sent or now - moved_at > REPORT_SETTLE_S or now - start > BURST_TIMEOUT_S:
                break
            time.sleep(0.02)
        self._mode("idle")
        span = report["last"] - start if report["count"] else math.nan
        return {"sent": sent, "delivered": report["count"], "send_s": sent_at - start, "span_s": span,
                "dropped": report.get("dropped", 0), "rejected": report.get("rejected", 0)}


# ==================================================================================================
# the echo process
# ==================================================================================================
def echo_main(connect: str, fleet: str, parent: int, poll_sleep: float = POLL_SLEEP_S) -> int:
    """Echo (or count) what arrives on the ping keys; obey the control key. Exits on ``quit``, or when
    the parent process is gone."""
    from agent.net import wire
    from agent.net.keys import Keys
    from agent.net.zenoh_transport import ZenohTransport, client_config

    keys = _Keys(fleet)
    transport = ZenohTransport("echo", Keys(fleet), client_config([connect]), [keys.queue_ping], liveliness=False)
    session = transport.session
    model = _model()
    codec = Codec("echo", "ping", model)
    commands: queue.Queue = queue.Queue()
    state = {"mode": "idle", "count": 0, "first": 0.0, "last": 0.0, "rejected": 0, "dropped0": 0}
    bare_pub = session.declare_publisher(keys.bare_pong)
    reply_pub = session.declare_publisher(keys.ctl_reply)

    def on_bare(sample) -> None:
        data = sample.payload.to_bytes()
        mode = state["mode"]
        if mode == "bare-echo":
            bare_pub.put(data)
        elif mode == "bare-count":
            now = time.time()
            if not state["count"]:
                state["first"] = now
            state["count"] += 1
            state["last"] = now

    session.declare_subscriber(keys.bare_ping, on_bare)
    session.declare_subscriber(keys.ctl, lambda s: commands.put(s.payload.to_bytes()))
    seq = 0

    def handle(raw: bytes) -> bool:
        """Apply one command; False on quit."""
        try:
            msg = json.loads(raw)
        except ValueError:
            return True
        op = msg.get("op")
        if op == "quit":
            return False
        if op == "mode":
            transport.drain()
            state.update(mode=msg.get("mode", "idle"), count=0, first=0.0, last=0.0, rejected=0,
                         dropped0=transport.dropped)
        reply = {"id": msg.get("id"), "op": op, "pid": os.getpid()}
        if op == "report":
            reply.update(count=state["count"], first=state["first"], last=state["last"],
                         rejected=state["rejected"], dropped=transport.dropped - state["dropped0"])
        reply_pub.put(json.dumps(reply).encode())
        return True

    try:
        while os.getppid() == parent:
            mode = state["mode"]
            if not mode.startswith(("queue", "agent")):
                try:
                    raw = commands.get(timeout=0.5)
                except queue.Empty:
                    continue
                if not handle(raw):
                    break
                continue
            try:  # queue and agent modes: busy-poll the transport like the pinging side, between commands
                raw = commands.get_nowait()
            except queue.Empty:
                raw = None
            if raw is not None:
                if not handle(raw):
                    break
                continue
            items = transport.drain()
            if not items:
                time.sleep(poll_sleep)
                continue
            for item in items:
                if mode == "queue-echo":
                    transport.publish(keys.queue_pong, item.data)
                    continue
                if mode.startswith("agent"):
                    try:
                        env, traj = codec.decode(item.data)
                    except wire.DecodeError:
                        state["rejected"] += 1
                        continue
                if mode == "agent-echo":
                    seq += 1
                    transport.publish(keys.queue_pong, codec.encode(traj, seq, env.stamp, env.seq))
                else:
                    now = time.time()
                    if not state["count"]:
                        state["first"] = now
                    state["count"] += 1
                    state["last"] = now
    finally:
        transport.close()
    return 0


# ==================================================================================================
# report
# ==================================================================================================
def report(result: dict, console=None) -> None:
    """Print the tables of a :func:`run` result."""
    console = console or common.make_console()
    s, env = result["settings"], result["environment"]
    console.print(
        f"[bold]{NAME}[/bold]  {'quick' if s['quick'] else 'full'} run: {s['round_trips_per_path']:,} round trips "
        f"and {s['blocks']} bursts of {s['burst']:,} messages per path, interleaved in {s['blocks']} blocks.  "
        f"{common.machine_line(env, {'zenoh': 'eclipse-zenoh', 'msgpack': 'msgpack'})}.  Load average "
        f"before/after: {s['load_average_before'][0]:.2f} / "
        f"{s['load_average_after'][0]:.2f}",
        highlight=False,
    )
    rows = {r["path"]: r for r in result["rows"]}
    bare = rows["bare"]
    labels = {
        "bare": "bare Zenoh: publisher + callback, raw bytes",
        "queue": "ZenohTransport publish + drain() poll, raw bytes",
        "agent": "agent: ZenohTransport + wire encode/decode of a track",
    }

    def rel(row, key):
        return "" if row is bare else f" ({common.fmt_ratio(row[key] / bare[key])})"

    rtt_rows = [
        [labels[p], f"{r['message_bytes']:,}", f"{r['round_trips']:,}", r["lost"],
         *(common.fmt_us(r[k]) + rel(r, k) for k in ("rtt_median_us", "rtt_p90_us", "rtt_p99_us", "rtt_mean_us")),
         common.fmt_us(r["one_way_median_us"])]
        for p, r in rows.items()
    ]
    common.print_table(
        console, "Round trip ping -> router -> echo -> router -> ping (µs; ÷ bare in brackets)",
        [("path", "left"), "bytes", "round trips", "lost", "median", "p90", "p99", "mean", "one hop (median/2)"],
        rtt_rows,
        "Both ends are Zenoh clients of one router on loopback (the skymesh run deployment): one hop = one "
        "agent-to-agent message through the router.\nBare waits on a threading.Event set by its callback; the "
        f"other paths busy-poll drain() with a {s['poll_sleep_s'] * 1e6:g} µs sleep, on both ends; the agent path "
        "also encodes and decodes (with validation) on both ends.",
    )
    thr_rows = [
        [labels[p], f"{r['throughput_msgs_s']:,.0f}" + rel(r, "throughput_msgs_s"), f"{r['throughput_mb_s']:,.1f}",
         f"{r['send_rate_msgs_s']:,.0f}", f"{100 * r['delivered_share']:.1f} %",
         ", ".join(f"{x:,.0f}" for x in r["throughput_bursts_msgs_s"])]
        for p, r in rows.items()
    ]
    common.print_table(
        console, "Throughput, one way (delivered messages per second; ÷ bare in brackets)",
        [("path", "left"), "msgs/s (median)", "MB/s", "sender msgs/s", "delivered", ("per burst", "left")],
        thr_rows,
        "Bursts sent back to back with the default congestion control (DROP); delivered = counted (agent path: "
        "decoded and validated) by the echo; rate = delivered / (last arrival - first send).",
    )
    c = result["codec"]
    agent, queue_row = rows["agent"], rows["queue"]
    predicted = queue_row["rtt_median_us"] + 2 * (c["encode"] + c["decode"])
    predicted_in_loop = queue_row["rtt_median_us"] + 2 * c["ping_side_in_round_trips"]
    console.print(
        f"Codec (median µs per message), in a hot loop in this process: encode (encode_trajectory + wire.encode) "
        f"{common.fmt_us(c['encode'])}, decode + validate (wire.decode + decode_trajectory) "
        f"{common.fmt_us(c['decode'])} (v1 decoder {common.fmt_us(c['decode_v1'])}: "
        f"{common.fmt_ratio(c['decode_speedup'])} faster; a flood message with 40 agents' acks "
        f"{common.fmt_us(c['decode_flood'])} vs {common.fmt_us(c['decode_flood_v1'])}: "
        f"{common.fmt_ratio(c['decode_flood_speedup'])}); measured on the ping side inside the agent round trips: "
        f"encode + decode "
        f"{common.fmt_us(c['ping_side_in_round_trips'])}.\nQueue RTT + 2 x (encode + decode) = "
        f"{common.fmt_us(predicted)} µs (hot loop) / {common.fmt_us(predicted_in_loop)} µs (in the round trips) vs "
        f"agent RTT {common.fmt_us(agent['rtt_median_us'])} µs.",
        highlight=False,
    )
    r, q = result["ratios"], result["ratios_queue_over_bare"]
    console.print(
        f"agent ÷ bare: RTT median {common.fmt_ratio(r['rtt_median'])}, p99 {common.fmt_ratio(r['rtt_p99'])}; "
        f"throughput {common.fmt_ratio(r['throughput'])} "
        f"({agent['throughput_msgs_s']:,.0f} vs {bare['throughput_msgs_s']:,.0f} msgs/s).  Of which the queue + "
        f"polling alone: RTT median {common.fmt_ratio(q['rtt_median'])}, "
        f"throughput {common.fmt_ratio(q['throughput'])}",
        highlight=False,
    )
    g = result["goals"]
    console.print(
        f"{common.verdict(g['decode_speedup_pass'])}  track message decoded {common.fmt_ratio(g['decode_speedup'])} "
        f"faster than v1 (goal >= {DECODE_SPEEDUP_GOAL:g}x)   {common.verdict(g['hop_pass'])}  agent hop "
        f"{common.fmt_ratio(r['rtt_median'])} bare Zenoh (goal <= {HOP_GOAL:g}x)",
        highlight=False,
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m mesh_sim.bench.transport",
                                description="The echo process of `skymesh bench transport` (hidden mode).")
    p.add_argument("--echo", action="store_true", help="run as the echo process")
    p.add_argument("--connect", required=True, help="the benchmark's router endpoint")
    p.add_argument("--fleet", required=True, help="the benchmark's fleet name")
    p.add_argument("--parent", type=int, required=True, help="PID of the benchmark process (exit when it is gone)")
    p.add_argument("--poll-sleep", type=float, default=POLL_SLEEP_S, help="busy-poll sleep [s]")
    args = p.parse_args(argv)
    if not args.echo:
        p.error("only --echo mode runs from the command line; use `skymesh bench transport`")
    return echo_main(args.connect, args.fleet, args.parent, args.poll_sleep)


if __name__ == "__main__":
    sys.exit(main())
