"""The fleet network's per-message path: per-link specs, fault hooks and disconnected nodes.

With none of these the fleet network impairs a tick's messages as one batch of arrays
(:meth:`FleetNetwork.route <swarmbox.core.fleet.network.FleetNetwork.route>`). With any of them it
walks the tick's messages in send order, as :meth:`SimMedium._route <swarmbox.net.medium.SimMedium>`
does for each (message, destination):

- the link's own spec (``network.links``, else the default) draws from the run's ``network``
  generator: one uniform for the jitter (if any), then one for the loss (if any);
- then every hook in installation order sees ``(message, src, dst, t)`` and may drop the message
  (the first reason wins) or add delay; the fault hooks draw from their own generators, per target,
  in message order — the order of this walk;
- a message for a disconnected node (a crashed drone's) is dropped as ``unreachable``.

A hook receives the message object; a Report of the fleet's batch has none (its fields live in
arrays) and is handed over as ``None`` — the shipped fault hooks look only at ``src`` and ``dst``.

Delivery order: SimMedium hands over the messages with the default constant delay from a FIFO and
the others (a delay a hook or a link changed) from a heap, FIFO first; :func:`split` and
:func:`arrived` keep the second kind apart (``FleetNetwork.late``) in the heap's order.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from swarmbox.core.fleet.rows import concat, take
from swarmbox.core.rows import NO_TEXT, TEXTS

if TYPE_CHECKING:
    from swarmbox.core.fleet.network import FleetNetwork

#: a fault hook: (message or None, src, dst, t) -> None, or (drop reason or "", extra delay s)
Hook = Callable[[object, int, int, float], "tuple[str, float] | None"]
_UNREACHABLE = TEXTS.code("unreachable")


class Link(NamedTuple):
    """One link's impairments (the fields of ``swarmbox.net.medium.LinkSpec``)."""

    latency_s: float = 0.0
    jitter_s: float = 0.0
    loss_prob: float = 0.0


def each(net: FleetNetwork, rng: np.random.Generator, out: np.ndarray,
         t: float) -> tuple[np.ndarray, np.ndarray]:
    """``(delay_s, drop reason code or NO_TEXT)`` of every message of ``out``, one after the other."""
    m = len(out)
    delay = np.empty(m)
    reason = np.full(m, NO_TEXT, dtype=np.int64)
    default = Link(net.latency_s, net.jitter_s, net.loss_prob)
    links, hooks, gone, objects = net.links, net.hooks, net.gone.tolist(), net.kept
    columns = (out["src"].tolist(), out["dst"].tolist(), out["dsti"].tolist(), out["obj"].tolist())
    for i, (src, dst, dsti, key) in enumerate(zip(*columns, strict=True)):
        spec = links.get((src, dst), default) if links else default
        d, why = spec.latency_s, ""
        if spec.jitter_s:
            d += spec.jitter_s * rng.random()
        if spec.loss_prob and rng.random() < spec.loss_prob:
            why = "loss"
        if hooks:
            msg = objects[key][0] if key >= 0 else None
            for hook in hooks:
                verdict = hook(msg, src, dst, t)
                if verdict is not None:
                    why = why or verdict[0]
                    d += verdict[1]
        if not why and gone[dsti]:
            why = "unreachable"
        delay[i] = d
        if why:
            reason[i] = TEXTS.code(why)
    return delay, reason


def split(net: FleetNetwork, out: np.ndarray, delay: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """The messages SimMedium queues in its FIFO (the default constant delay) and the rest."""
    if net.jitter_s:   # every message goes to the heap, which ``pending`` is kept in the order of
        return out, None
    late = delay != net.latency_s
    if not late.any():
        return out, None
    return take(out, ~late), take(out, late)


def arrived(net: FleetNetwork, due: np.ndarray) -> np.ndarray:
    """This tick's arrivals: ``due`` (the FIFO's), then the heap's; those for a disconnected node
    dropped as ``unreachable`` (stamped with their arrival), the rest returned in hand-over order."""
    late = net.late
    if len(late):
        n = int(np.searchsorted(late["arrival"], net.time.t_s + 1e-12, side="right"))
        if n:
            due, net.late = (concat([due, late[:n]]) if len(due) else late[:n]), late[n:]
    if not len(due):
        return due
    gone = net.gone[due["dsti"]]
    if gone.any():
        lost = due[gone]
        net.drop_rows(lost, lost["arrival"], _UNREACHABLE)
        net.release(lost["obj"])
        net.release(lost["data"])
        due = take(due, ~gone)
    return due
