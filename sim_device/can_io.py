"""CAN side of the simulated governor: measurement bursts out, excitation commands in (python-can + cantools).

Frames are defined in ``fcrlive_sim.dbc`` beside this module. Every published controller sample goes out as
one burst of six classic 8-byte frames, always in the same order, starting with ``GOV_Counter``
(0x180 sample_counter, status) then 0x181 time, 0x182 speed/grid_freq, 0x183 power/mech_power,
0x184 gate, 0x185 excitation; a receiver groups a burst by the counter frame that opens it. Floats are
IEEE (``SIG_VALTYPE_``), so CAN carries the same precision as the Modbus float32 registers.
``GOV_ExcitationCmd`` (0x200) carries excitation offset, enable and heartbeat in one frame and goes through
the same safety (clamp, enable, heartbeat timeout) as the Modbus holding registers.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from pathlib import Path

import can
import cantools

from fcrlive.canbus import close_bus
from fcrlive.errors import ConfigError

DBC_PATH = Path(__file__).with_name("fcrlive_sim.dbc")
TX_ORDER = ("GOV_Counter", "GOV_Time", "GOV_Speed", "GOV_Power", "GOV_Gate", "GOV_Excitation")
CMD_MESSAGE = "GOV_ExcitationCmd"
SAMPLE_MESSAGE = "GOV_Sample"
INTERFACES = ("virtual", "udp_multicast", "socketcan")

log = logging.getLogger("sim_device.can")


def load_dbc(path: str | Path | None = None) -> cantools.database.can.Database:
    """The shipped DBC (or another one with the same message and signal names)."""
    return cantools.database.load_file(str(path or DBC_PATH))


def open_bus(channel: str, interface: str, **kwargs) -> can.BusABC:
    """Open a python-can bus; ConfigError (one line) if it cannot be opened."""
    if interface not in INTERFACES:
        raise ConfigError(f"unknown CAN interface {interface!r}; use one of {', '.join(INTERFACES)}")
    try:
        return can.Bus(channel=channel, interface=interface, **kwargs)
    except Exception as exc:
        raise ConfigError(f"cannot open CAN channel {channel!r} on {interface}: {exc}") from None


class CanLink:
    """Publishes snapshots as DBC frames and hands received excitation commands to ``on_command``."""

    def __init__(
        self,
        channel: str,
        interface: str = "virtual",
        *,
        on_command: Callable[[float, int, int], None],
        dbc_path: str | Path | None = None,
        bus_kwargs: dict | None = None,
    ):
        self.channel = channel
        self.interface = interface
        self.bus_kwargs = dict(bus_kwargs or {})
        self.db = load_dbc(dbc_path)
        self._tx = [self.db.get_message_by_name(n) for n in TX_ORDER]
        self._cmd = self.db.get_message_by_name(CMD_MESSAGE)
        self._sample = next((m for m in self.db.messages if m.name == SAMPLE_MESSAGE), None)
        self._on_command = on_command
        self.bus: can.BusABC | None = None
        self._notifier: can.Notifier | None = None
        self.frames_sent = 0
        self.commands_received = 0
        self.send_errors = 0

    def open(self, loop: asyncio.AbstractEventLoop) -> None:
        self.bus = open_bus(self.channel, self.interface, **self.bus_kwargs)
        self._notifier = can.Notifier(self.bus, [self._on_message], timeout=0.1, loop=loop)

    def close(self) -> None:
        close_bus(self._notifier, self.bus)
        self._notifier = self.bus = None

    def send_snapshot(self, values: dict[str, float]) -> None:
        """One burst of frames for one controller sample (values keyed by signal name)."""
        if self.bus is None:
            return
        for msg in self._tx:
            data = msg.encode({s.name: values[s.name] for s in msg.signals}, strict=False)
            frame = can.Message(arbitration_id=msg.frame_id, data=data, is_extended_id=False)
            try:
                self.bus.send(frame)
                self.frames_sent += 1
            except can.CanError as exc:
                self.send_errors += 1
                if self.send_errors in (1, 10, 100, 1000):
                    log.warning("CAN send failed (%d so far): %s", self.send_errors, exc)

    def send_sample(self, counter: int, fields: tuple[str, ...], values: tuple[float, ...]) -> None:
        """One CAN FD frame ``GOV_Sample`` per controller sample (rolling counter; buffered acquisition)."""
        if self.bus is None or self._sample is None:
            return
        sig = {"seq_counter": counter, **{f"seq_{f}": v for f, v in zip(fields, values, strict=True)}}
        try:
            data = self._sample.encode({s.name: sig.get(s.name, 0.0) for s in self._sample.signals},
                                       strict=False)
            self.bus.send(can.Message(arbitration_id=self._sample.frame_id, data=data, is_fd=True,
                                      is_extended_id=False))
            self.frames_sent += 1
        except (can.CanError, ValueError) as exc:
            self.send_errors += 1
            if self.send_errors in (1, 10, 100, 1000):
                log.warning("CAN FD sample frame failed (%d so far): %s", self.send_errors, exc)

    def _on_message(self, msg: can.Message) -> None:
        if msg.arbitration_id != self._cmd.frame_id or msg.is_extended_id or msg.is_error_frame:
            return
        try:
            d = self._cmd.decode(msg.data)
        except Exception as exc:
            log.warning("undecodable excitation command frame %s: %s", msg.data.hex(), exc)
            return
        self.commands_received += 1
        self._on_command(float(d["excitation_offset"]), int(d["excitation_enable"]), int(d["heartbeat"]))
