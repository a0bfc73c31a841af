"""`python -m sim_device` as a process: one-line errors (exit 2), readiness, map file, timed fault flags."""

from __future__ import annotations

import asyncio
import os
import socket
import subprocess
import sys

import pytest
from test_sim_device_modbus import IN_COUNT, IN_START, UNIT, connect, read_block

from sim_device.__main__ import main as cli_main
from sim_device.registers import load_map

ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}


def run_cli(*args: str, timeout: float = 30) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sim_device", *args], capture_output=True, text=True, timeout=timeout, env=ENV
    )


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--speed", "0"], "speed must be > 0"),
        (["--speed", "fast"], "speed must be a number"),
        (["--port", "70000"], "port must be 0..65535"),
        (["--word-order", "middle"], "invalid choice"),
        (["--preset", "nope"], "unknown preset 'nope'"),
        (["--fault-exception", "grumpy"], "unknown Modbus exception 'grumpy'"),
        (["--can-interface", "pigeon"], "invalid choice"),
        (["--heartbeat-timeout", "-1"], "heartbeat timeout must be > 0"),
        (["--bogus"], "unrecognized arguments"),
    ],
)
def test_bad_flags_one_line_exit_2(args, fragment, capsys):
    """In-process (no interpreter start per case): argparse and user errors end as one line, status 2."""
    try:
        status = cli_main(args)
    except SystemExit as exc:  # argparse
        status = exc.code
    err = capsys.readouterr().err
    assert status == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0] and "Traceback" not in err, err
    assert lines[0].startswith("fcrlive-sim-device: error:")


def test_bad_plant_file_and_port_in_use(tmp_path):
    """As a real process: exit status 2 and exactly one line on stderr."""
    r = run_cli("--plant", str(tmp_path / "missing.toml"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "missing.toml" in r.stderr
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        r = run_cli("--port", str(port))
    assert r.returncode == 2, r
    assert r.stderr.strip().splitlines() == [
        f"fcrlive-sim-device: error: port {port} on 127.0.0.1 is already in use"
    ]


async def _start(*args: str):
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sim_device", "--port", "0", "--log-level", "WARNING", *args,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, env=ENV,
    )  # fmt: skip
    line = (await asyncio.wait_for(proc.stdout.readline(), 30)).decode()
    if not line.startswith("listening on "):
        proc.kill()
        raise AssertionError(line + (await proc.stderr.read()).decode())
    _host, port = line.split()[-1].rsplit(":", 1)
    return proc, int(port)


async def _stop(proc) -> int:
    if proc.returncode is None:
        proc.terminate()
    return await asyncio.wait_for(proc.wait(), 15)


async def test_cli_serves_the_written_map_and_stops_on_sigterm(tmp_path):
    mapfile = tmp_path / "device.toml"
    proc, port = await _start("--speed", "10", "--word-order", "little", "--write-map", str(mapfile))
    try:
        rmap = load_map(mapfile)
        assert rmap.word_order == "little" and rmap.points == load_map().points
        client = await connect(port)
        v = await read_block(client, rmap)
        assert abs(v["speed"] - 1.0) < 0.01 and v["device_time"] == v["sample_counter"] * 0.02
        h = rmap.decode_block("holding", 100, (await client.read_holding_registers(100, count=12)).registers)
        assert (
            h["rated_power"] == 300.0
            and h["nominal_freq"] == 50.0
            and h["excitation_limit"] == pytest.approx(0.1)
        )
        client.close()
    finally:
        assert await _stop(proc) == 0
    assert "Traceback" not in (await proc.stderr.read()).decode()


async def test_cli_timed_exception_fault_and_periodic_restart():
    proc, port = await _start(
        "--speed", "5", "--fault-exception", "busy", "--fault-after", "1.0", "--fault-for", "1.0",
        "--fault-restart-every", "4", "--restart-downtime", "0.3",
    )  # fmt: skip
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    seen: list[tuple[float, str, int]] = []  # (t, "ok"/"exc6"/"down", counter)
    client = None
    try:
        while loop.time() - t0 < 5.5:
            try:
                if client is None or not client.connected:
                    if client is not None:
                        client.close()
                    client = await connect(port, timeout=0.3)
                rr = await client.read_input_registers(IN_START, count=IN_COUNT, device_id=UNIT)
                if rr.isError():
                    seen.append((loop.time() - t0, f"exc{rr.exception_code}", -1))
                else:
                    seen.append(
                        (loop.time() - t0, "ok", load_map().decode("sample_counter", rr.registers[:2]))
                    )
            except Exception:
                seen.append((loop.time() - t0, "down", -1))
                client = None
            await asyncio.sleep(0.05)
    finally:
        if client is not None:
            client.close()
        await _stop(proc)
    kinds = [k for _, k, _ in seen]
    # healthy, then DEVICE_BUSY for about a second, then healthy again, then a restart
    first_exc = kinds.index("exc6")
    assert "ok" in kinds[:first_exc]
    last_exc = len(kinds) - 1 - kinds[::-1].index("exc6")
    t_first, t_last = seen[first_exc][0], seen[last_exc][0]
    assert 0.8 < t_first < 1.6 and 0.6 < t_last - t_first < 1.3
    assert "ok" in kinds[last_exc:]
    counters = [(t, n) for t, k, n in seen if k == "ok"]
    drops = [i for i in range(1, len(counters)) if counters[i][1] < counters[i - 1][1]]
    assert len(drops) == 1 and 3.5 < counters[drops[0]][0] < 5.0  # the restart reset the counter
