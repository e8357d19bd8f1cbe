"""Which MAVLink streams a PX4 bridge reads, at which rates, and the unrequested ones it asks PX4 to stop.

PX4 streams many messages by default; each costs the bridge parsing time (a Python process decodes a
few thousand packets a second, a PX4 instance sends about 400). On connecting, and again when the
link comes back, the bridge sets the rates it was configured with (``MAV_CMD_SET_MESSAGE_INTERVAL``);
a stream nobody asked for that keeps arriving is switched off, a few times at most.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from swarmbox.hal.mavlink.codec import CMD_SET_MESSAGE_INTERVAL, MSG, Decoder
from swarmbox.hal.px4.params import LinkConfig

#: the messages the bridge decodes (every other id is skipped by its header, and counted)
WANTED = frozenset(MSG[m] for m in (
    "HEARTBEAT", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "GPS_RAW_INT", "SYS_STATUS",
    "EXTENDED_SYS_STATE", "COMMAND_ACK", "STATUSTEXT", "HIL_STATE_QUATERNION", "PARAM_VALUE"))
SILENCE_AFTER = 20   # unrequested packets of one id before asking PX4 to stop them
_MAX_TRIES, _RETRY_S = 3, 5.0

#: submit(command, params, quiet=...): a COMMAND_LONG through the vehicle's command tracker
Submit = Callable[..., None]


class Streams:
    """The stream rates of one vehicle's link: set on (re)connection, unrequested ones silenced."""

    def __init__(self, cfg: LinkConfig, decoder: Decoder, submit: Submit) -> None:
        self._cfg, self._decoder, self._submit = cfg, decoder, submit
        self._silenced: dict[int, tuple[int, float, int]] = {}   # msg id -> (tries, at_s, count then)

    def configure(self) -> None:
        """Ask for every configured rate (a rate <= 0 switches the stream off)."""
        for name, hz in self._cfg.message_rates_hz:
            interval_us = 1e6 / hz if hz > 0 else -1.0
            self._submit(CMD_SET_MESSAGE_INTERVAL, (float(MSG[name]), interval_us))

    def silence_unrequested(self, now_s: float) -> None:
        """Ask the autopilot to stop streams nobody asked for; again after a while if they keep coming."""
        if not self._cfg.silence_unrequested:
            return
        for msg_id, count in self._decoder.skipped_ids.items():
            if count < SILENCE_AFTER:
                continue
            tries, at_s, then = self._silenced.get(msg_id, (0, -math.inf, 0))
            if tries < _MAX_TRIES and now_s - at_s >= _RETRY_S and count - then >= SILENCE_AFTER:
                self._silenced[msg_id] = (tries + 1, now_s, count)
                self._submit(CMD_SET_MESSAGE_INTERVAL, (float(msg_id), -1.0), quiet=True)
