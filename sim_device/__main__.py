"""``python -m sim_device`` / ``fcrlive-sim-device``: the simulated governor as a Modbus TCP (and CAN) device.

Prints ``listening on HOST:PORT`` on stdout when ready; logs go to stderr. Bad flags, unknown presets,
bad plant files and a port in use give a one-line error and exit status 2.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import math
import signal
import sys
from pathlib import Path

from fcrlive.errors import UserError

PROG = "fcrlive-sim-device"
log = logging.getLogger("sim_device")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def _positive(name: str, allow_zero: bool = False):
    def conv(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, not {text!r}") from None
        if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
            raise argparse.ArgumentTypeError(f"{name} must be {'>= 0' if allow_zero else '> 0'}, not {text}")
        return v

    return conv


def _port(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"port must be an integer, not {text!r}") from None
    if not 0 <= v <= 65535:
        raise argparse.ArgumentTypeError(f"port must be 0..65535, not {v}")
    return v


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog=PROG,
        description="Simulated hydro governor: a Modbus TCP (and CAN) device driven by the plant model.",
    )
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=_port, default=5020, help="TCP port (default 5020; 0 = any free port)")
    p.add_argument(
        "--unit-id", type=int, default=None, help="Modbus unit id (default from the register map: 1)"
    )
    p.add_argument(
        "--speed",
        type=_positive("speed"),
        default=1.0,
        help="simulated seconds per wall second (default 1 = real time)",
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument("--preset", default="paper-plant1", help="plant preset (default paper-plant1)")
    src.add_argument("--plant", type=Path, metavar="FILE.toml", help="plant description file")
    p.add_argument("--seed", type=int, default=0, help="random seed of the grid noise (default 0)")
    p.add_argument("--snr-db", type=float, default=12.0, help="noise level of the simulator (default 12 dB)")
    p.add_argument(
        "--word-order",
        choices=("big", "little"),
        default="big",
        help="order of 16-bit words in 32/64-bit values (default big)",
    )
    p.add_argument(
        "--excitation-limit-hz",
        type=_positive("excitation limit", allow_zero=True),
        default=0.1,
        help="clamp on the excitation offset (default 0.1 Hz)",
    )
    p.add_argument(
        "--heartbeat-timeout",
        type=_positive("heartbeat timeout"),
        default=2.0,
        help="wall-clock seconds without a heartbeat change before the offset is reset (default 2)",
    )
    p.add_argument(
        "--can", metavar="CHANNEL", help="also speak CAN on this channel (frames: fcrlive_sim.dbc)"
    )
    p.add_argument(
        "--can-interface",
        choices=("virtual", "udp_multicast", "socketcan"),
        default="virtual",
        help="python-can interface (default virtual; udp_multicast across processes)",
    )
    p.add_argument("--can-port", type=_port, help="UDP port of the udp_multicast interface (default 43113)")
    p.add_argument(
        "--write-map",
        type=Path,
        metavar="FILE.toml",
        help="write the effective register map (word order, unit id) to FILE and continue",
    )
    p.add_argument(
        "--buffer-slots",
        type=int,
        metavar="N",
        help="slots of the ring buffer of controller samples, a power of two <= 4096 (default: the map's, "
        "more when accelerated: 4 wall seconds)",
    )
    p.add_argument("--duration", type=_positive("duration"), help="stop after this many wall seconds")
    p.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    f = p.add_argument_group("fault injection")
    f.add_argument("--fault-hang", action="store_true", help="accept requests but never answer")
    f.add_argument(
        "--fault-exception",
        metavar="CODE",
        help="answer every request with this Modbus exception: busy, failure or a number",
    )
    f.add_argument(
        "--fault-delay-ms",
        type=_positive("delay", allow_zero=True),
        default=0.0,
        help="answer every request this many ms late",
    )
    f.add_argument("--fault-freeze", action="store_true", help="input registers stop changing")
    f.add_argument("--fault-nan", action="store_true", help="measured floats read as NaN")
    f.add_argument(
        "--fault-after",
        type=_positive("fault start", allow_zero=True),
        default=0.0,
        help="start the standing faults above after this many wall seconds (default 0)",
    )
    f.add_argument(
        "--fault-for",
        type=_positive("fault duration"),
        help="clear the standing faults after this many wall seconds (default: never)",
    )
    f.add_argument(
        "--fault-drop-every",
        type=_positive("drop period"),
        metavar="S",
        help="close every client connection every S wall seconds",
    )
    f.add_argument(
        "--fault-restart-every",
        type=_positive("restart period"),
        metavar="S",
        help="restart the device (counters, setpoints, plant reset) every S wall seconds",
    )
    f.add_argument(
        "--restart-downtime",
        type=_positive("downtime", allow_zero=True),
        default=1.0,
        help="seconds the port stays closed during a restart (default 1)",
    )
    return p


def _load_plant(args):
    from fcrlive.plant.params import preset

    if args.plant is None:
        return preset(args.preset)
    from fcrlive.plant.description import load_plant

    return load_plant(args.plant)


async def _run(args) -> int:
    from sim_device.device import SimGovernor
    from sim_device.faults import parse_exception_code

    exc_code = parse_exception_code(args.fault_exception) if args.fault_exception else None
    plant = _load_plant(args)
    dev = SimGovernor(
        plant,
        host=args.host,
        port=args.port,
        speed=args.speed,
        seed=args.seed,
        snr_db=args.snr_db,
        word_order=args.word_order,
        unit_id=args.unit_id,
        excitation_limit_hz=args.excitation_limit_hz,
        heartbeat_timeout_s=args.heartbeat_timeout,
        can_channel=args.can,
        can_interface=args.can_interface,
        can_kwargs={"port": args.can_port} if args.can_port else None,
        buffer_slots=args.buffer_slots,
    )
    if args.write_map:
        try:
            args.write_map.write_text(dev.register_map.to_toml(), encoding="utf-8")
        except OSError as exc:
            raise UserError(
                f"cannot write register map: {exc.strerror or exc}", str(args.write_map)
            ) from None
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):
            loop.add_signal_handler(sig, stop.set)
    standing = {
        "hang": args.fault_hang,
        "exception": exc_code,
        "delay_ms": args.fault_delay_ms,
        "freeze": args.fault_freeze,
        "nan": args.fault_nan,
    }
    has_standing = any(v for v in standing.values())

    async with dev:
        print(f"listening on {dev.host}:{dev.port}", flush=True)
        can_note = f", CAN {args.can_interface}:{args.can}" if args.can else ""
        log.info(
            "speed %gx, Tc %g s, excitation limit %g Hz, heartbeat timeout %g s%s",
            dev.speed,
            dev.dt,
            dev.excitation_limit_hz,
            dev.heartbeat_timeout_s,
            can_note,
        )
        tasks = []

        async def standing_faults():
            await asyncio.sleep(args.fault_after)
            dev.faults.set(**standing)
            if args.fault_for:
                await asyncio.sleep(args.fault_for)
                dev.faults.clear()

        async def every(period, action):
            while True:
                await asyncio.sleep(period)
                await action()

        async def drop():
            dev.faults.drop_connections()

        async def restart():
            await dev.faults.restart(args.restart_downtime)

        if has_standing:
            tasks.append(asyncio.create_task(standing_faults()))
        if args.fault_drop_every:
            tasks.append(asyncio.create_task(every(args.fault_drop_every, drop)))
        if args.fault_restart_every:
            tasks.append(asyncio.create_task(every(args.fault_restart_every, restart)))
        try:
            if args.duration:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), args.duration)
            else:
                await stop.wait()
        finally:
            for t in tasks:
                t.cancel()
            for t in tasks:
                with contextlib.suppress(asyncio.CancelledError):
                    await t
        log.info(
            "stopping after %d samples (%.1f simulated s), %d requests served, %d clock slips",
            dev.sample_counter,
            dev.sample_counter * dev.dt,
            dev.requests,
            dev.slips,
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=args.log_level, stream=sys.stderr, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    logging.getLogger("pymodbus").setLevel(logging.WARNING if args.log_level != "DEBUG" else logging.DEBUG)
    try:
        return asyncio.run(_run(args))
    except UserError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return exc.exit_status
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
