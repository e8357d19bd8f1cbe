"""mavsim: a MAVLink vehicle process that answers like PX4 in OFFBOARD, flying the ``sim`` dynamics.

It is the stand-in that lets every machine (and CI) test the ``px4`` bridge over real UDP sockets
on 127.0.0.1, several vehicles at once::

    python -m swarmbox.hal.mavsim.process --instance 0 --home-n 0 --home-e 0            # PX4's port plan
    python -m swarmbox.hal.mavsim.process --instance 3 --home-n -6 --home-e -6 --port-plan 50123:0 --speed 4

``--instance i`` gives system id i+1; ``--home-n/--home-e`` place the vehicle (metres from
``--origin-lat/--origin-lon/--origin-alt``), or ``--home-lat/--home-lon/--home-alt`` do (as
PX4_HOME_*); the port plan is PX4's (listen on 14580+i, send to 14540+i, or to 14549 for i > 9)
or ``REMOTE:LOCAL`` (0 = any free port). ``--speed k`` runs the
simulation k times faster than the wall clock, stream rates and loss timeouts in simulation time,
as PX4's PX4_SIM_SPEED_FACTOR does; a loaded CPU slows the simulation instead of skipping steps.
The process ends on SIGTERM/SIGINT, when ``--parent-pid`` is gone, or after ``--max-wall-s``.
SIGUSR1 switches its radio off and on (nothing sent or received meanwhile: a link loss, while the
vehicle flies on and runs its own failsafes).
"""

from __future__ import annotations

import argparse
import math
import os
import select
import signal
import sys
import time
from collections.abc import Sequence

import numpy as np

from swarmbox.hal.mavlink.codec import (
    CMD_REQUEST_MESSAGE,
    CMD_SET_MESSAGE_INTERVAL,
    FRAME_LOCAL_NED,
    MSG,
    RESULT_ACCEPTED,
    RESULT_UNSUPPORTED,
    CommandLongMsg,
    Decoder,
    HeartbeatMsg,
    SetpointTargetMsg,
)
from swarmbox.hal.mavlink.frames import GeoFrame
from swarmbox.hal.mavlink.signing import KEY_ENV, signing_key_of
from swarmbox.hal.mavsim.commander import Commander
from swarmbox.hal.mavsim.link import DEFAULT_RATES_HZ, AutopilotSocket, Streams, VehicleEncoder, VehicleState
from swarmbox.hal.safety import SafetyLimits
from swarmbox.hal.sim.backend import SimBackend
from swarmbox.hal.sim.params import SimParams

MAX_CATCH_UP_STEPS = 20
#: the vehicle's own envelope; the mission's geofence is the bridge's job
VEHICLE_LIMITS = SafetyLimits(geofence_radius_m=1e6, max_jump_m=1e6, max_alt_m=1e4)
WANTED = frozenset({MSG["HEARTBEAT"], MSG["COMMAND_LONG"], MSG["SET_POSITION_TARGET_LOCAL_NED"]})


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="python -m swarmbox.hal.mavsim.process",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--instance", type=int, required=True, help="vehicle index i (system id i+1)")
    ap.add_argument("--system-id", type=int, default=None, help="override the system id")
    ap.add_argument("--home-n", type=float, default=0.0, help="home, metres north of the origin")
    ap.add_argument("--home-e", type=float, default=0.0, help="home, metres east of the origin")
    ap.add_argument("--origin-lat", type=float, default=47.397742)
    ap.add_argument("--origin-lon", type=float, default=8.545594)
    ap.add_argument("--origin-alt", type=float, default=488.0, help="AMSL, metres")
    ap.add_argument("--home-lat", type=float, default=None, help="home latitude (replaces --home-n/-e)")
    ap.add_argument("--home-lon", type=float, default=None)
    ap.add_argument("--home-alt", type=float, default=None, help="home AMSL, metres")
    ap.add_argument("--port-plan", default="px4", help="'px4' (listen 14580+i, send 14540+i) or REMOTE:LOCAL")
    ap.add_argument("--speed", type=float, default=1.0, help="simulation speed factor")
    ap.add_argument("--tick-s", type=float, default=0.01, help="physics step (simulation seconds)")
    ap.add_argument("--seed", type=int, default=None, help="GNSS noise seed (default: the instance)")
    ap.add_argument("--sim-param", action="append", default=[], metavar="KEY=VALUE",
                    help="a sim backend parameter (conf/backend/sim.yaml key); repeatable")
    ap.add_argument("--offboard-loss", choices=("hold", "land", "rtl"), default="hold")
    ap.add_argument("--refuse", action="append", default=[], metavar="COMMAND",
                    help="answer this command (arm, takeoff, set_mode, ...) with DENIED: fault injection")
    ap.add_argument("--parent-pid", type=int, default=None, help="exit when this process is gone")
    ap.add_argument("--max-wall-s", type=float, default=3600.0)
    args = ap.parse_args(argv)
    if not (args.speed > 0 and math.isfinite(args.speed) and args.tick_s > 0):
        ap.error("--speed and --tick-s must be > 0")
    return args


def ports_of(plan: str, instance: int) -> tuple[int, int]:
    """(remote, local) ports of a port plan."""
    if plan == "px4":   # px4-rc.mavlink: the remote port is pinned to 14549 past instance 9
        return (14540 + instance if instance <= 9 else 14549), 14580 + instance
    remote, sep, local = plan.partition(":")
    if not (sep and remote.isdigit() and local.isdigit()):
        raise ValueError(f"--port-plan must be 'px4' or REMOTE:LOCAL, got {plan!r}")
    return int(remote), int(local)


def home_of(args: argparse.Namespace) -> GeoFrame:
    """The vehicle's home (its local frame's origin), from lat/lon/alt or from metres off the origin."""
    if args.home_lat is not None and args.home_lon is not None:
        alt = args.origin_alt if args.home_alt is None else args.home_alt
        return GeoFrame(args.home_lat, args.home_lon, alt)
    lat, lon, _ = GeoFrame(args.origin_lat, args.origin_lon, args.origin_alt).geodetic_of(
        (args.home_n, args.home_e, 0.0))
    return GeoFrame(lat, lon, args.origin_alt)


def sim_params_of(items: Sequence[str]) -> dict[str, float | str]:
    """The vehicle's sim parameters. A paced one-vehicle process gains nothing from the compiled
    kernel and must not stall for its loading mid-flight, so ``jit`` is ``never`` unless given."""
    out: dict[str, float | str] = {"jit": "never"}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--sim-param expects KEY=VALUE, got {item!r}")
        out[key] = SimParams.parse(key, value)
    SimParams.from_kwargs(out)
    return out


class MavsimProgram:
    """One vehicle: its simulation, commander, MAVLink link and the wall-clock pacing loop."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.system_id = args.system_id or args.instance + 1
        self.home = home_of(args)
        seed = args.instance if args.seed is None else args.seed
        self.sim = SimBackend(homes_ned_m=[(0.0, 0.0, 0.0)], tick_s=args.tick_s,
                              rng=np.random.default_rng(seed), limits=VEHICLE_LIMITS,
                              **sim_params_of(args.sim_param))
        self.commander = Commander(self.sim, home_alt_m=self.home.alt_m, speed=args.speed,
                                   offboard_loss_action=args.offboard_loss, refuse=frozenset(args.refuse))
        remote, local = ports_of(args.port_plan, args.instance)
        self.link = AutopilotSocket(local, remote)
        # MAVLink 2 signing, as a signing autopilot does it: with a key (handed over in the environment,
        # never on the command line) the vehicle signs what it sends and obeys only packets signed with it
        key_text = os.environ.get(KEY_ENV)
        self.signed = bool(key_text)
        key = signing_key_of(key_text) if key_text else None
        self.encoder = VehicleEncoder(self.system_id, self.home, signing_key=key)
        self.streams = Streams(DEFAULT_RATES_HZ)
        self.decoder = Decoder(WANTED, key)
        self.stop = False
        self._gnss_seq, self._gnss_t_s = 0, 0.0
        self.ignored = 0   # packets for another system, or setpoints it cannot fly

    # ---- incoming -----------------------------------------------------------------------------
    def receive(self) -> None:
        for data, addr in self.link.receive():
            for pkt, value in self.decoder.decode(data):
                self.link.adopt(addr)
                if type(value) is CommandLongMsg:
                    self._on_command(pkt.system_id, pkt.component_id, value)
                elif type(value) is SetpointTargetMsg:
                    self._on_setpoint(value)
                elif type(value) is not HeartbeatMsg:
                    self.ignored += 1
        self.link.flush()

    def _on_command(self, src_sys: int, src_comp: int, cmd: CommandLongMsg) -> None:
        if cmd.target_system not in (0, self.system_id):
            self.ignored += 1
            return
        if cmd.command == CMD_SET_MESSAGE_INTERVAL:
            ok = self.streams.set_interval(int(cmd.params[0]), cmd.params[1])
            result = RESULT_ACCEPTED if ok else RESULT_UNSUPPORTED
        elif cmd.command == CMD_REQUEST_MESSAGE:
            msg_id = int(cmd.params[0])
            result = RESULT_ACCEPTED if self.streams.streamable(msg_id) else RESULT_UNSUPPORTED
            if result == RESULT_ACCEPTED:
                self.link.queue(self.encoder.encode(msg_id, self.state()))
        else:
            result = self.commander.on_command(cmd.command, cmd.params)
        self.link.queue(self.encoder.command_ack(cmd.command, result, (src_sys, src_comp)))
        self._send_texts()

    def _on_setpoint(self, msg: SetpointTargetMsg) -> None:
        sp = msg.setpoint
        if (msg.target_system not in (0, self.system_id) or msg.frame != FRAME_LOCAL_NED or sp is None
                or not all(map(math.isfinite, sp.ned))):
            self.ignored += 1
            return
        self.commander.on_setpoint(sp)

    # ---- outgoing -----------------------------------------------------------------------------
    def state(self) -> VehicleState:
        c, tel = self.commander, self.commander.telemetry()
        if tel.gnss_seq != self._gnss_seq:
            self._gnss_seq, self._gnss_t_s = tel.gnss_seq, c.t_s
        true_pos = tel.true_pos_ned_m or tel.pos_ned_m
        n, e, d = self.sim.true_vel_ned_m_s[0].tolist()
        return VehicleState(c.t_s, tel.armed, c.nav, c.landed_state(), c.ready_to_arm(), tel.battery_frac,
                            tel.pos_ned_m, tel.vel_ned_m_s, tel.yaw_rad, tel.gnss_ned_m, self._gnss_t_s,
                            true_pos, (n, e, d))

    def send_streams(self) -> None:
        due = self.streams.due(self.sim.t_s)
        if due:
            state = self.state()
            for msg_id in due:
                self.link.queue(self.encoder.encode(msg_id, state))
        self._send_texts()
        self.link.flush()

    def _send_texts(self) -> None:
        for severity, text in self.commander.texts:
            for packet in self.encoder.statustext(severity, text):
                self.link.queue(packet)
        self.commander.texts.clear()

    # ---- the loop -----------------------------------------------------------------------------
    def run(self) -> int:
        a, dt = self.args, self.args.tick_s
        wall0 = start = time.monotonic()
        sock = self.link.sock
        direct_child = a.parent_pid is not None and os.getppid() == a.parent_pid
        while not self.stop:
            now = time.monotonic()
            if now - start > a.max_wall_s or (a.parent_pid and _gone(a.parent_pid, direct_child)):
                break
            self.receive()
            target_s, steps = (now - wall0) * a.speed, 0
            while self.sim.t_s + dt <= target_s + 1e-9 and steps < MAX_CATCH_UP_STEPS:
                self.commander.step(dt)
                self.send_streams()
                steps += 1
            if steps == MAX_CATCH_UP_STEPS:   # overloaded: slow the simulation down, never skip
                wall0 = time.monotonic() - self.sim.t_s / a.speed
            wait_s = wall0 + (self.sim.t_s + dt) / a.speed - time.monotonic()
            if wait_s > 0:
                select.select([sock], [], [], min(wait_s, 0.1))
        self.link.close()
        return 0


def _gone(pid: int, direct_child: bool) -> bool:
    """Whether the watched process has ended (a child is re-parented when its parent dies)."""
    if direct_child:
        return os.getppid() != pid
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        program = MavsimProgram(args)
    except (ValueError, TypeError, OSError) as exc:
        print(f"mavsim {args.instance}: {exc}", file=sys.stderr)
        return 2

    def _stop(_signum: int, _frame: object) -> None:
        program.stop = True

    def _toggle_radio(_signum: int, _frame: object) -> None:
        program.link.radio_on = not program.link.radio_on
        state = "on" if program.link.radio_on else "off"
        print(f"mavsim {args.instance}: radio {state} at t={program.sim.t_s:.2f} s", file=sys.stderr,
              flush=True)

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    signal.signal(signal.SIGUSR1, _toggle_radio)
    link, name = program.link, f"mavsim {args.instance}"
    print(f"{name}: system {program.system_id}, listening on 127.0.0.1:{link.local_port}, "
          f"sending to {link.peer[1]}, speed {args.speed:g}, signing {'on' if program.signed else 'off'}",
          file=sys.stderr, flush=True)
    code = program.run()
    print(f"{name}: stopped at t={program.sim.t_s:.1f} s (sim), sent {link.tx_bytes} B, "
          f"received {link.rx_bytes} B, ignored {program.ignored} packets, "
          f"garbage {program.decoder.garbage_bytes} B, unsigned or wrongly signed "
          f"{program.decoder.signature_rejected} packets", file=sys.stderr, flush=True)
    return code


if __name__ == "__main__":
    sys.exit(main())
