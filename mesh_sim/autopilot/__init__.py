"""``skymesh autopilot``: a MAVLink autopilot simulator that behaves like PX4 SITL for a subset, one process
per vehicle, around skymesh's kinematic vehicle models (issue 14).

Towards an offboard computer and a ground station it is PX4 SITL instance ``I``: the same ports, system id,
HEARTBEAT, flight modes, commands and acknowledgements, offboard protocol, parameters and telemetry rates,
as far as each module's docstring says. One module a job:

* :mod:`~mesh_sim.autopilot.flight` — the state machine (arming, modes, takeoff, land, RTL, offboard
  timeout) over the kinematic model; :mod:`~mesh_sim.autopilot.battery`, :mod:`~mesh_sim.autopilot.gimbal`;
* :mod:`~mesh_sim.autopilot.offboard` — SET_POSITION_TARGET_LOCAL_NED -> model setpoint;
* :mod:`~mesh_sim.autopilot.router`, :mod:`~mesh_sim.autopilot.commands`, :mod:`~mesh_sim.autopilot.params`,
  :mod:`~mesh_sim.autopilot.ftp` — what each received message does and what is answered;
* :mod:`~mesh_sim.autopilot.telemetry`, :mod:`~mesh_sim.autopilot.streams` — the messages and their rates;
* :mod:`~mesh_sim.autopilot.link`, :mod:`~mesh_sim.autopilot.delay_line`, :mod:`~mesh_sim.autopilot.counters`
  — UDP, latency, and bad input counted;
* :mod:`~mesh_sim.autopilot.simulator` — the real-time loop; :mod:`~mesh_sim.autopilot.options` and
  :mod:`~mesh_sim.autopilot.cli` — the command line; :mod:`~mesh_sim.autopilot.process` — starting and
  stopping simulators from tests and benchmarks.
"""
