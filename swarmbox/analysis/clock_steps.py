"""Clock steps: a node whose clock jumps (a resynchronisation, a fault, a reboot of its time source) is
unified in pieces, one *life* per stretch between jumps, instead of one line through the jump.

Detection (a residual test on the node's own log): a drone writes a state row every
``state_every_ticks`` ticks, so its local time minus ``tick x tick_s`` is its clock offset (plus a
drift that moves it by microseconds per row). A change of that residual between two consecutive rows
larger than ``ClockOptions.step_min_s`` is a step; a linear drift never makes one. The ground and the
network are the reference and have no state log: their steps are not detected.

Each row of the node then belongs to a life:

- rows of its tables with a ``tick`` column: by tick;
- rows of its messages table (read without ticks): in log order, the row where the log turns from the
  old life to the new one, chosen so that the fewest rows lie on the wrong side of the step's time
  under the offsets the state log gives each life (the rows of a backward step repeat local times:
  only their order tells them apart);
- send times it stamped on the messages other nodes received (``t_sent_s`` with ``src`` = the node):
  the life whose send time falls at or before the receive time and closest to it (a message cannot
  arrive before it was sent, nor take a clock step's length).

Each life is then a clock of its own for :func:`swarmbox.analysis.unify.estimate_clocks`, with the id
``node + life x LIFE_STRIDE``; the clock table names the node and the life.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

#: Clock id of a node's life ``k`` >= 1: ``node + k * LIFE_STRIDE`` (drone ids stay far below it).
LIFE_STRIDE = 1 << 20


@dataclass(frozen=True, slots=True)
class Step:
    node: int
    tick: int          # first tick of the new life
    t_s: float         # tick x tick_s: the step's time on the run's tick clock
    jump_s: float      # local reading after - before, at the same instant (approximate)


def find_steps(state: pd.DataFrame, tick_s: float, min_step_s: float) -> list[Step]:
    """Every jump of a drone's clock larger than ``min_step_s`` in its state log."""
    if not len(state) or not np.isfinite(tick_s) or tick_s <= 0:
        return []
    node = state["node"].to_numpy()
    tick = state["tick"].to_numpy(dtype="float64")
    resid = state["t_s"].to_numpy(dtype="float64") - tick * tick_s
    order = np.lexsort((tick, node))
    node, tick, resid = node[order], tick[order], resid[order]
    jump = np.diff(resid)
    at = np.flatnonzero((node[1:] == node[:-1]) & (np.abs(jump) > min_step_s)) + 1
    return [Step(int(node[i]), int(tick[i]), float(tick[i] * tick_s), float(jump[i - 1])) for i in at]


def _offsets(state: pd.DataFrame, steps: list[Step], tick_s: float) -> dict[tuple[int, int], float]:
    """Approximate offset of each (node, life) from its state rows: median of local - tick time."""
    out = {}
    resid = state["t_s"].to_numpy(dtype="float64") - state["tick"].to_numpy(dtype="float64") * tick_s
    life = lives_by_tick(state["node"].to_numpy(), state["tick"].to_numpy(), steps)
    frame = pd.DataFrame({"node": state["node"].to_numpy(), "life": life, "r": resid})
    for (n, k), r in frame.groupby(["node", "life"])["r"]:
        out[(int(n), int(k))] = float(r.median())
    return out


def lives_by_tick(node: np.ndarray, tick: np.ndarray, steps: list[Step]) -> np.ndarray:
    """Life of every row from its node and tick (0 for a node with no step)."""
    life = np.zeros(len(node), dtype=np.int64)
    for s in steps:
        life += ((node == s.node) & (tick >= s.tick)).astype(np.int64)
    return life


def _lives_in_order(t_local: np.ndarray, steps: list[Step], offsets: dict, node: int,
                    tol: float) -> np.ndarray:
    """Life of each row of one node's table in log order, from local times only (see module doc)."""
    life = np.zeros(len(t_local), dtype=np.int64)
    start = 0
    for k, s in enumerate(steps, start=1):
        rest = t_local[start:]
        before = rest - offsets.get((node, k - 1), 0.0) > s.t_s + tol     # wrong if left in life k - 1
        after = rest - offsets.get((node, k), 0.0) < s.t_s - tol           # wrong if put in life k
        wrong = np.concatenate([[0], np.cumsum(before)]) + np.concatenate([np.cumsum(after[::-1])[::-1], [0]])
        cut = start + int(np.argmin(wrong))
        life[cut:] = k
        start = cut
    return life


def _sender_lives(t_sent: np.ndarray, t_recv_u: np.ndarray, src: np.ndarray, steps: list[Step],
                  offsets: dict, tol: float) -> np.ndarray:
    """Life of the sender's clock for each stamped send time (see module doc)."""
    life = np.zeros(len(t_sent), dtype=np.int64)
    for node in sorted({s.node for s in steps}):
        mine = np.flatnonzero(src == node)
        if not len(mine):
            continue
        n_lives = 1 + sum(s.node == node for s in steps)
        cand = np.stack([t_sent[mine] - offsets.get((node, k), 0.0) for k in range(n_lives)])
        wait = t_recv_u[mine] - cand
        wait = np.where(wait >= -tol, wait, np.inf)   # a send after its receive is no candidate
        life[mine] = np.argmin(wait, axis=0)
    return life


def clock_ids(tables: dict[str, pd.DataFrame], steps: list[Step], tick_s: float) -> dict[str, np.ndarray]:
    """Per table: the clock id of every row (``node`` when it has no step), and ``messages_src``: the
    clock id of the sender's stamp ``t_sent_s`` of every messages row."""
    offsets = _offsets(tables["state"], steps, tick_s)
    out: dict[str, np.ndarray] = {}
    for name, frame in tables.items():
        node = frame["node"].to_numpy().astype(np.int64)
        if "tick" in frame:
            life = lives_by_tick(node, frame["tick"].to_numpy(), steps)
        else:
            life = np.zeros(len(frame), dtype=np.int64)
            t_local = frame["t_s"].to_numpy(dtype="float64")
            for n in sorted({s.node for s in steps}):
                rows = np.flatnonzero(node == n)
                life[rows] = _lives_in_order(t_local[rows], [s for s in steps if s.node == n], offsets,
                                             n, tick_s)
        out[name] = node + life * LIFE_STRIDE
    msgs = tables["messages"]
    by_id = {n + k * LIFE_STRIDE: o for (n, k), o in offsets.items()}
    offset = pd.Series(out["messages"]).map(by_id).fillna(0.0).to_numpy(dtype="float64")
    approx_u = msgs["t_s"].to_numpy(dtype="float64") - offset   # a receiver's row on the tick clock
    src = msgs["src"].fillna(-1).to_numpy().astype(np.int64)
    life = _sender_lives(msgs["t_sent_s"].to_numpy(dtype="float64"), approx_u, src, steps, offsets, tick_s)
    out["messages_src"] = src + life * LIFE_STRIDE
    return out


def describe(steps: list[Step], clocks: pd.DataFrame) -> list[str]:
    """One line per step for the run's problems."""
    lines = []
    for s in steps:
        row = clocks[(clocks["node"] == s.node) & (clocks["life"] > 0)]
        row = row[(row["from_u"] - s.t_s).abs() == (row["from_u"] - s.t_s).abs().min()]
        jump = float(row["step_s"].iloc[0]) if len(row) else s.jump_s
        lines.append(f"node {s.node}: clock step of {jump:+.6f} s at about {s.t_s:.3f} s; "
                     "unified in pieces, one clock before and one after")
    return lines
