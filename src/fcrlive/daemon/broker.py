"""MQTT brokers for tests and the demo: embedded amqtt (in-process) or a private Mosquitto.

Both are async context managers listening on a free loopback port (``.host``, ``.port``) and can
be stopped and started again on the same port (to test reconnects and queued delivery)::

    async with start_broker() as broker:      # Mosquitto when on PATH, else amqtt
        ...  # broker.port

Never touches a system broker on 1883: each instance gets its own port and temporary config.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import shutil
import socket
import subprocess
import tempfile
from pathlib import Path


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free a moment ago on ``host``."""
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


async def wait_listening(host: str, port: int, timeout: float = 10.0) -> None:
    """Wait until ``host:port`` accepts TCP connections (TimeoutError otherwise)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while True:
        try:
            _, w = await asyncio.open_connection(host, port)
            w.close()
            with contextlib.suppress(OSError):
                await w.wait_closed()
            return
        except OSError:
            if loop.time() > deadline:
                raise TimeoutError(f"nothing listening on {host}:{port} after {timeout} s") from None
            await asyncio.sleep(0.02)


class EmbeddedBroker:
    """amqtt 0.12 broker in this process (MQTT 3.1.1, retained messages, wills), anonymous access."""

    kind = "amqtt"

    def __init__(self, host: str = "127.0.0.1", port: int = 0):
        self.host = host
        self.port = port or free_port(host)
        self._broker = None

    async def start(self) -> None:
        """Start (again) on the same port."""
        from amqtt.broker import Broker

        # CRITICAL: amqtt logs an ERROR for every TCP probe (wait_listening) that sends no CONNECT
        logging.getLogger("amqtt").setLevel(logging.CRITICAL)
        cfg = {
            "listeners": {"default": {"type": "tcp", "bind": f"{self.host}:{self.port}"}},
            "plugins": {"amqtt.plugins.authentication.AnonymousAuthPlugin": {"allow_anonymous": True}},
        }
        self._broker = Broker(cfg)
        await self._broker.start()
        await wait_listening(self.host, self.port)

    async def stop(self) -> None:
        """Shut the broker down (clients see their connection drop)."""
        if self._broker is not None:
            await self._broker.shutdown()
            self._broker = None

    async def __aenter__(self) -> EmbeddedBroker:
        await self.start()
        return self

    async def __aexit__(self, *exc) -> None:
        await self.stop()


class MosquittoBroker:
    """A private ``mosquitto`` process on a free loopback port with a temporary config.

    ``extra_config`` lines are appended to the generated config (e.g. TLS or password settings).
    """

    kind = "mosquitto"

    def __init__(self, host: str = "127.0.0.1", port: int = 0, extra_config: str = "",
                 allow_anonymous: bool = True):
        exe = shutil.which("mosquitto")
        if exe is None:
            raise FileNotFoundError("mosquitto is not on PATH")
        self.exe = exe
        self.host = host
        self.port = port or free_port(host)
        self.extra_config = extra_config
        self.allow_anonymous = allow_anonymous
        self._dir = tempfile.TemporaryDirectory(prefix="fcrlive-mosquitto-")
        self._proc: subprocess.Popen | None = None

    @property
    def config_path(self) -> Path:
        return Path(self._dir.name) / "mosquitto.conf"

    async def start(self) -> None:
        """Start (again) on the same port."""
        self.config_path.write_text(
            f"listener {self.port} {self.host}\n"
            f"allow_anonymous {'true' if self.allow_anonymous else 'false'}\n"
            "persistence false\n"
            f"log_dest file {Path(self._dir.name) / 'mosquitto.log'}\n"
            f"{self.extra_config}\n")
        self._proc = subprocess.Popen([self.exe, "-c", str(self.config_path)], stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL)
        try:
            await wait_listening(self.host, self.port)
        except TimeoutError:
            await self.stop()
            raise

    async def stop(self) -> None:
        """Terminate the process (SIGTERM, then SIGKILL after 5 s)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        proc.terminate()
        try:
            await asyncio.to_thread(proc.wait, 5)
        except subprocess.TimeoutExpired:
            proc.kill()
            await asyncio.to_thread(proc.wait, 5)

    async def __aenter__(self) -> MosquittoBroker:
        await self.start()
        return self

    async def __aexit__(self, *exc) -> None:
        await self.stop()
        self._dir.cleanup()


def start_broker(prefer: str = "auto", host: str = "127.0.0.1") -> EmbeddedBroker | MosquittoBroker:
    """A broker object to ``async with``: Mosquitto when ``prefer`` is "auto" and it is on PATH."""
    if prefer == "mosquitto" or (prefer == "auto" and shutil.which("mosquitto")):
        return MosquittoBroker(host)
    return EmbeddedBroker(host)
