"""``fcrlive demo``: the whole system on embedded defaults, results shown live as they arrive over MQTT.

Starts, in this process, the simulated governor (``sim_device.SimGovernor``, paper plant 1, accelerated
``--speed`` times), an embedded MQTT broker (amqtt; ``--broker mosquitto`` for a private Mosquitto, or
``--mqtt-host`` to use a running broker) and the daemon itself (``Service``: Modbus polling, a temporary
SQLite store, identification in a worker process, MQTT publishing). A subscriber prints every result, and
after ``--identifications`` results a summary against the simulated plant's truth.

Window lengths are given in SIMULATED minutes; the daemon's wall-clock windows are these divided by the
speed. The governor is the paper's plant 1 with its 50 Hz digital controller (Tc = 20 ms), accelerated
``--speed`` times, and the daemon reads EVERY controller sample from the governor's ring buffer
(buffered acquisition, docs/buffered-acquisition.md): Z_cu needs them all (docs/daemon.md), and what the
daemon identifies then does not depend on the machine's load.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the CLI imports its commands at start-up: pydantic models load only when run
    from fcrlive.daemon.payloads import ResultPayload

NAME = "demo"
HELP = ("run the whole system on embedded defaults (simulated governor, MQTT broker, daemon); "
        "show results live")


MAX_SPEED = 40.0
"""Above this the simulated governor (one Python process) cannot both compute and serve 50 samples × speed
per wall second on a small machine."""
EXC_ON = "ON (white noise 0.1 Hz through the safety guard, into the SIMULATED governor only)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--speed", type=float, default=20.0,
                        help=f"simulated seconds per wall second, at most {MAX_SPEED:g} (default 20: 1000 "
                             "controller samples per wall second)")
    parser.add_argument("--window-min", type=float, default=30.0,
                        help="identification window [simulated min] (default 30)")
    parser.add_argument("--every-min", type=float, default=10.0,
                        help="identification period [simulated min] (default 10)")
    parser.add_argument("--identifications", type=int, default=3,
                        help="stop after this many identification results (default 3)")
    parser.add_argument("--minutes", type=float, default=None,
                        help="stop after this many WALL minutes at the latest (default: enough for the "
                             "identifications)")
    parser.add_argument("--excitation", action=argparse.BooleanOptionalAction, default=True,
                        help="write the paper's white-noise excitation (0.1 Hz) through the safety guard "
                             "into the SIMULATED governor (default on: Z_cu, max|S|, TSO checks need it; "
                             "--no-excitation: Z_u, droop and max|G_1| only)")
    parser.add_argument("--broker", choices=("embedded", "mosquitto", "auto"), default="embedded",
                        help="MQTT broker to start: embedded amqtt (default), a private mosquitto, or auto")
    parser.add_argument("--mqtt-host", default=None, help="use this running broker instead of starting one")
    parser.add_argument("--mqtt-port", type=int, default=1883, help="port of --mqtt-host (default 1883)")
    parser.add_argument("--seed", type=int, default=1, help="noise seed of the simulated grid (default 1)")
    parser.add_argument("--store", default=None, metavar="FILE.sqlite",
                        help="keep the SQLite store here (default: a temporary file)")
    parser.add_argument("--summary-json", metavar="FILE", default=None,
                        help="also write the truth and every window's results as JSON (droop in %%; a value "
                             "the quality rule withholds is null)")
    parser.add_argument("--log-level", default="WARNING", choices=("DEBUG", "INFO", "WARNING", "ERROR"),
                        help="daemon log level on stderr (default WARNING)")


def _check(args) -> None:
    from fcrlive.errors import UserError

    if not (args.speed > 0 and args.speed <= MAX_SPEED):
        raise UserError(f"--speed must be in (0, {MAX_SPEED:g}], not {args.speed:g}")
    if args.identifications < 1:
        raise UserError("--identifications must be at least 1")
    if args.window_min / args.speed < 0.1:
        raise UserError(f"--window-min {args.window_min:g} at --speed {args.speed:g} is shorter than the "
                        "daemon's smallest window (0.1 wall minutes)")
    if args.every_min <= 0 or (args.minutes is not None and args.minutes <= 0):
        raise UserError("--every-min and --minutes must be positive")


def _fmt_ci(d: dict | None, scale: float = 1.0, fmt: str = "{:.2f}") -> str:
    if not d or d.get("value") is None:
        return "n/a"
    s = fmt.format(d["value"] * scale)
    lo, hi = (d.get("ci95") or [None, None])[:2]
    if lo is not None and hi is not None:
        s += f" [{fmt.format(lo * scale)}, {fmt.format(hi * scale)}]"
    return s


def _verdict(tso: dict | None, key: str) -> str:
    """PASS / FAIL / UNDECIDED (the report's ``decision``) with the band margin and its 95 % interval."""
    if not tso or key not in tso:
        return "unknown"
    v = tso[key]
    word = (v.get("decision") or ("pass" if v["pass"] else "fail")).upper()
    m, lo, hi = (v.get(k) for k in ("stability_margin_band", "stability_margin_band_lower",
                                     "stability_margin_band_upper"))
    if m is None:
        return word
    iv = "" if lo is None or hi is None else f" [{lo:.2f}, {hi:.2f}]"
    return f"{word} (min|1+FG| {m:.2f}{iv})"


def _level(msg: dict) -> str:
    """The quality rule's level of a ``result/latest`` payload ("ok" for daemons without the rule)."""
    return (msg.get("result_quality") or {}).get("level", "ok")


def result_line(n: int, msg: dict, speed: float) -> str:
    """One terminal line for a ``result/latest`` payload: a rejected result shows why, never its numbers
    (the daemon keeps them off the headline topics too); uncertain numbers are marked."""
    q = msg["quality"]
    w = msg["window"]
    lost = (q.get("counts") or {}).get("missing", 0)
    head = (f"#{n} {(w['end'] - w['start']) * speed / 60:.1f} sim-min window, data ok "
            f"{100 * q['ok_fraction']:.1f} % ({lost} samples lost, {q['gaps']} gaps)")
    if not msg["ok"]:
        return f"{head}: no result: {msg['error']}"
    r = msg["result"] or {}
    rq = msg.get("result_quality") or {}
    if _level(msg) == "rejected":
        return (f"{head}, method {r.get('method')}: result REJECTED, headline values kept: "
                f"{'; '.join(rq.get('reasons') or [])} ({msg['duration_s']:.1f} s)")
    per = rq.get("quantities") or {}

    def mark(key: str) -> str:
        # a droop from another method than the window's (lowband in a Z_cu report) says so
        other = (r.get(key) or {}).get("method")
        return (f" (from {other})" if other else "") + (
            " (uncertain)" if (per.get(key) or {}).get("level") == "uncertain" else "")

    return (f"{head}, method {r.get('method')}: droop {_fmt_ci(r.get('droop'), 100.0)} %{mark('droop')}, "
            f"max|S| {_fmt_ci(r.get('max_abs_s'))}{mark('max_abs_s')}, "
            f"max|G_1| {_fmt_ci(r.get('max_abs_g1'))}{mark('max_abs_g1')}, "
            f"FCR-N {_verdict(r.get('tso'), 'fcrn')}, FCR-D {_verdict(r.get('tso'), 'fcrd')}, "
            f"result {_level(msg)} ({msg['duration_s']:.1f} s)")


def summary_lines(results: list[dict], truth: dict, kd: float, wall_s: float, speed: float) -> list[str]:
    """The closing summary against the simulated plant's truth (rejected results left out)."""
    done = [m for m in results if m["ok"] and m["result"]]
    ok = [m["result"] for m in done if _level(m) != "rejected"]
    levels = [_level(m) for m in done]
    droop_true = 1.0 / (1.0 / truth["g1_static"] - kd) if truth.get("g1_static") else truth.get("droop")
    lines = [f"demo summary: {len(results)} identification(s), {len(done)} with a result "
             f"({levels.count('ok')} ok, {levels.count('uncertain')} uncertain, "
             f"{levels.count('rejected')} rejected by the quality rule), in {wall_s:.0f} s "
             f"wall ({wall_s * speed / 60:.0f} simulated min at speed {speed:g})"]

    def row(name: str, true: float | None, key: str, scale: float, unit: str) -> str:
        vals = [r[key]["value"] * scale for r in ok if r.get(key) and r[key].get("value") is not None]
        t = "?" if true is None else f"{true * scale:.3g}{unit}"
        if not vals:
            why = "all rejected by the quality rule" if done and not ok else "not identifiable from this data"
            return f"  {name:<9} truth {t:<8} estimates: none ({why})"
        mean = sum(vals) / len(vals)
        err = "" if true is None else f", error of the mean {mean - true * scale:+.2f}{unit}"
        return (f"  {name:<9} truth {t:<8} estimates {', '.join(f'{v:.3g}' for v in vals)}{unit}"
                f" (mean {mean:.3g}{unit}{err})")

    lines.append(row("droop", droop_true, "droop", 100.0, " %"))
    lines.append(row("max|S|", truth.get("max_S"), "max_abs_s", 1.0, ""))
    lines.append(row("max|G_1|", truth.get("max_G1"), "max_abs_g1", 1.0, ""))
    for key, name in (("fcrn", "FCR-N"), ("fcrd", "FCR-D")):
        words = [_verdict(r.get("tso"), key).split(" ")[0] for r in ok if (r.get("tso") or {}).get(key)]
        if words:
            lines.append(f"  {name:<9} verdicts {', '.join(words)} (UNDECIDED: the 95 % interval of a margin "
                         "reaches over its limit)" if "UNDECIDED" in words else
                         f"  {name:<9} verdicts {', '.join(words)}")
    methods = sorted({m["result"].get("method") for m in done})
    if methods:
        lines.append(f"  method(s): {', '.join(str(m) for m in methods)}"
                     + ("; without excitation S, G_p and the TSO checks are not identifiable (Z_u)"
                        if methods == ["zu"] else ""))
    if not done:
        lines.append("  no identification produced a result: see the lines above")
    return lines


def summary_json(results: list[dict], truth: dict, kd: float) -> dict:
    """``--summary-json``: the plant's truth and every window's published numbers (droop in %), read from the
    typed ``result/latest`` payload (:class:`fcrlive.daemon.payloads.ResultPayload` and its
    :class:`~fcrlive.analysis.report.IdentifyReport`). A number the quality rule withholds, or one the
    method cannot give, is null; ``ci95`` is the report's 95 % interval [lower, upper], an end null where
    it is unknown; ``tso`` the TSO decision per product (pass / fail / undecided), null when withheld;
    ``reasons`` says why, per null number."""
    from fcrlive.analysis.report import ValueCI
    from fcrlive.daemon.payloads import ResultPayload

    droop_true = 1.0 / (1.0 / truth["g1_static"] - kd) if truth.get("g1_static") else truth.get("droop")
    out = {"truth": {"droop": None if droop_true is None else 100.0 * droop_true,
                     "max_abs_s": truth.get("max_S"), "max_abs_g1": truth.get("max_G1"),
                     "controller_rate_hz": 1.0 / truth["dt"]}, "windows": []}
    for m in results:
        p = ResultPayload.model_validate(m)
        r = p.result
        verdict = None if p.result_quality is None else p.result_quality.level
        withheld = not p.ok or r is None or verdict == "rejected"

        def num(v: ValueCI | None, scale: float = 1.0, withheld: bool = withheld) -> dict | None:
            if withheld or v is None or v.value is None:
                return None
            return {"value": v.value * scale, "ci95": [None if e is None else e * scale for e in v.ci95]}

        win = {
            "method": None if r is None else r.method, "verdict": verdict,
            "lost_samples": p.quality.counts.get("missing", 0),
            "droop": num(r and r.droop, 100.0), "max_abs_s": num(r and r.max_abs_s),
            "max_abs_g1": num(r and r.max_abs_g1),
            "tso": None if withheld or r.tso is None else {k: v.verdict for k, v in r.tso.items()}}
        win["reasons"] = _null_reasons(p, win)
        out["windows"].append(win)
    return out


_ZU_GIVES_NO = "Z_u (normal operation, no excitation) cannot give S, G_p or the TSO checks"


def _null_reasons(p: ResultPayload, win: dict) -> dict[str, str]:
    """Why each null number of a ``--summary-json`` window is null: the run's error, the quality rule's
    reasons, or the identification's own "not identifiable from this log" (the store that held the whole
    report is deleted when the demo ends, so the summary keeps the why)."""
    r, q = p.result, p.result_quality
    out: dict[str, str] = {}
    for key in ("droop", "max_abs_s", "max_abs_g1", "tso"):
        if win[key] is not None:
            continue
        if not p.ok or r is None:
            out[key] = p.error or "the run gave no result"
        elif q is not None and q.level == "rejected":
            out[key] = "rejected by the quality rule: " + "; ".join(q.reasons or ["(no reason given)"])
        elif key == "tso":
            out[key] = (r.not_identifiable.get("tso") or r.not_identifiable.get("gp")
                        or (_ZU_GIVES_NO if r.method == "zu" else "no TSO checks from this log"))
        else:
            v = getattr(r, key)
            out[key] = ((v.reason if v is not None else None) or r.not_identifiable.get(key)
                        or (_ZU_GIVES_NO if r.method == "zu" and key == "max_abs_s" else
                            "not identifiable from this log"))
    return out


async def _demo(args) -> int:
    import asyncio
    import contextlib
    import dataclasses
    import json
    import logging
    import shutil
    import tempfile
    import time
    from pathlib import Path

    import aiomqtt

    from fcrlive.daemon.broker import EmbeddedBroker, MosquittoBroker, start_broker
    from fcrlive.daemon.config import load_config
    from fcrlive.daemon.health import setup_logging
    from fcrlive.daemon.payloads import is_data_skip
    from fcrlive.daemon.service import Service
    from fcrlive.errors import UserError
    from fcrlive.plant.description import load_plant
    from sim_device import SimGovernor

    setup_logging(args.log_level)
    logging.getLogger("sim_device").setLevel(max(logging.WARNING, logging.getLogger().level))
    tmp = tempfile.TemporaryDirectory(prefix="fcrlive-demo-")
    store = Path(args.store) if args.store else Path(tmp.name) / "demo.sqlite"
    unit = "demo"
    async with contextlib.AsyncExitStack() as stack:
        stack.callback(tmp.cleanup)
        if args.mqtt_host:
            host, port, broker_kind = args.mqtt_host, args.mqtt_port, "external"
        else:
            if args.broker == "mosquitto" and not shutil.which("mosquitto"):
                raise UserError("--broker mosquitto: mosquitto is not on PATH (use --broker embedded)")
            broker = (EmbeddedBroker() if args.broker == "embedded" else
                      MosquittoBroker() if args.broker == "mosquitto" else start_broker())
            await stack.enter_async_context(broker)
            host, port, broker_kind = broker.host, broker.port, broker.kind
        # the simulated plant's description: Z_cu takes the controller from it (as a site's [unit] plant)
        plant_file = Path(tmp.name) / "plant.toml"
        plant_file.write_text('preset = "paper-plant1"\n')  # its governor: Tc = 20 ms, 50 Hz
        gov = await stack.enter_async_context(
            SimGovernor(load_plant(plant_file), port=0, speed=args.speed, seed=args.seed))
        # the map a site with a buffering governor writes: every controller sample from the ring buffer
        regmap = Path(tmp.name) / "registers.toml"
        regmap.write_text(dataclasses.replace(gov.register_map, acquisition="buffered").to_toml())
        truth_task = asyncio.create_task(asyncio.to_thread(gov.truth, True))
        speed = args.speed
        overrides = dict(
            unit={"name": unit, "rated_mw": gov.rated_mw, "f0": gov.f0, "kd": 0.1, "plant": str(plant_file)},
            source={"kind": "modbus", "modbus": {"host": "127.0.0.1", "port": gov.port,
                                                 "register_map": str(regmap)}},
            store={"path": str(store), "retention_hours": 24.0},
            identification={"every_min": args.every_min / speed, "window_min": args.window_min / speed,
                            "device_speed": speed},
            mqtt={"host": host, "port": port, "stats_interval_s": 5.0, "client_id": f"fcrlive-demo-{port}"},
            metrics={"enabled": False},
        )
        if args.excitation:
            overrides["excitation"] = excitation_settings(speed)
        cfg = load_config(None, **overrides)
        window_wall = args.window_min * 60 / speed
        every_wall = args.every_min * 60 / speed
        limit_s = args.minutes * 60 if args.minutes else (
            window_wall + every_wall * (args.identifications + 1) + 120.0)
        print(f"fcrlive demo: simulated governor (paper plant 1: droop 8 %, max|S| 1.29, max|G_1| 1.01) "
              f"on 127.0.0.1:{gov.port} at {speed:g}x, MQTT {broker_kind} broker on {host}:{port}, "
              f"store {store}")
        print(f"  buffered acquisition: every controller sample (50 Hz simulated, {50 * speed:.0f} per wall "
              f"second) from the governor's ring buffer; "
              f"a {args.window_min:g} sim-min window every {args.every_min:g} sim-min "
              f"({window_wall:.0f} s / {every_wall:.0f} s wall); excitation "
              f"{EXC_ON if args.excitation else 'off (Z_u)'}; "
              f"subscribe: mosquitto_sub -h {host} -p {port} -t 'fcrlive/{unit}/#' -v", flush=True)
        svc = Service(cfg, version="demo")
        stop = asyncio.Event()
        daemon = asyncio.create_task(svc.run(stop), name="daemon")
        results: list[dict] = []
        t0 = time.monotonic()
        last_live = 0.0
        try:
            async with asyncio.timeout(limit_s):
                async with aiomqtt.Client(host, port, identifier=f"fcrlive-demo-view-{port}") as client:
                    await client.subscribe(f"fcrlive/{unit}/result/latest", qos=1)
                    await client.subscribe(f"fcrlive/{unit}/live", qos=0)
                    async for m in client.messages:
                        if daemon.done():
                            break
                        msg = json.loads(m.payload)
                        if str(m.topic).endswith("/live"):
                            if time.monotonic() - last_live >= 15.0:
                                last_live = time.monotonic()
                                s = msg["signals"]
                                p = (s.get("power") or {}).get("mean")
                                f = (s.get("grid_freq") or {}).get("mean")
                                rate = f"  live: {msg['rate_hz']:.1f} samples/s"
                                print(f"{rate}, ok {msg['quality']['ok']}, P {p:.1f} MW, f {f:.3f} Hz"
                                      if p is not None and f is not None else f"{rate} (no good samples yet)",
                                      flush=True)
                            continue
                        if is_data_skip(msg):
                            print(f"  (window not full yet: {msg['error']})", flush=True)
                            continue
                        results.append(msg)
                        print(result_line(len(results), msg, speed), flush=True)
                        if len(results) >= args.identifications:
                            break
        except TimeoutError:
            print(f"fcrlive demo: stopped after {limit_s / 60:.1f} wall minutes", flush=True)
        finally:
            stop.set()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(daemon, 30)
        if daemon.done() and not daemon.cancelled() and daemon.exception() is not None:
            raise daemon.exception()
        truth = await truth_task
        for line in summary_lines(results, truth, 0.1, time.monotonic() - t0, speed):
            print(line)
        if args.summary_json:
            try:
                doc = summary_json(results, truth, 0.1)
                Path(args.summary_json).write_text(json.dumps(doc, indent=2) + "\n")
            except OSError as exc:
                raise UserError(f"cannot write: {exc.strerror or exc}", where=args.summary_json) from None
    return 0 if results else 1


def excitation_settings(speed: float) -> dict:
    """The demo's ``[excitation]``: enabled explicitly, with explicit limits (the paper's 0.1 Hz), r held
    0.5 simulated s as in the paper's study."""
    return {"enabled": True, "period_s": max(0.02, 0.5 / speed),
            "limits": {"amplitude_hz": 0.1, "holdoff_s": 1.0},
            "generator": {"kind": "white", "seed": 7}}


def run(args: argparse.Namespace) -> int:
    import asyncio

    _check(args)
    if args.excitation:
        try:
            import fcrlive.excitation.task  # noqa: F401
        except ImportError:
            from fcrlive.errors import UserError

            raise UserError("--excitation: the excitation writer is not available in this version") from None
    return asyncio.run(_demo(args))
