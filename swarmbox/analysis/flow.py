"""Send-to-receive matching of the messages table in Arrow: the message flow of a run.

A 1,000-drone minute logs about ten million message rows. Matching them with a pandas merge held
the whole table several times over (the sends, the receives, the merged frame and its sorted copy,
each with text columns); here the pandas columns are viewed as Arrow arrays (no copy for numbers or
Arrow-backed text), only the columns the flow needs are taken, receives are reduced to the first
arrival per ``(msg_id, dst)`` by a hash aggregation, and the join, the per-link maximum latency and
the final order are Arrow kernels. Only the finished flow becomes pandas.

The definitions (delivered, lost, in flight, counted) are those of :mod:`swarmbox.analysis.network`;
the result equals the former pandas computation row for row (``tests/analysis/test_flow.py``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from swarmbox.analysis.load import NET
from swarmbox.analysis.unify import T

LAT = "latency_ms"
_KEYS = ["msg_id", "dst"]


def _col(frame: pd.DataFrame, name: str, mask: np.ndarray, typ: pa.DataType) -> pa.Array:
    """``frame[name][mask]`` as an Arrow array of ``typ``; NaN becomes null (as pandas' notna sees it)."""
    values = frame[name].to_numpy()[mask] if typ != pa.string() else frame[name][mask]
    return pa.array(values, from_pandas=True).cast(typ)


def _first_arrivals(messages: pd.DataFrame, recv: np.ndarray) -> pa.Table:
    """Earliest unified receive time per (msg_id, receiving node): a re-delivered copy is not new."""
    recvs = pa.table({"msg_id": _col(messages, "msg_id", recv, pa.int64()),
                      "dst": _col(messages, "node", recv, pa.int64()),
                      "t_recv": _col(messages, T, recv, pa.float64())})
    recvs = recvs.filter(pc.is_valid(recvs["t_recv"]))   # a receive with no time says nothing
    return recvs.group_by(_KEYS).aggregate([("t_recv", "min")]).rename_columns([*_KEYS, "t_recv"])


def _first_drops(messages: pd.DataFrame, drop: np.ndarray) -> pa.Table:
    """The first logged drop reason per (msg_id, dst), in log order (drops are few)."""
    drops = pd.DataFrame({"msg_id": messages["msg_id"][drop].astype("int64"),
                          "dst": messages["dst"][drop].astype("int64"),
                          "drop_reason": messages["reason"][drop].astype("str")})
    drops = drops.drop_duplicates(_KEYS)
    return pa.table({"msg_id": pa.array(drops["msg_id"].to_numpy(), pa.int64()),
                     "dst": pa.array(drops["dst"].to_numpy(), pa.int64()),
                     "drop_reason": pa.array(drops["drop_reason"], pa.string())})


def _sends(messages: pd.DataFrame, send: np.ndarray) -> pa.Table:
    columns = {"msg_id": ("msg_id", pa.int64()), "type": ("type", pa.string()), "src": ("src", pa.int64()),
               "dst": ("dst", pa.int64()), "nbytes": ("nbytes", pa.float64()), "t_send": (T, pa.float64())}
    data = {name: _col(messages, col, send, typ) for name, (col, typ) in columns.items()}
    data["_row"] = pa.array(np.arange(int(send.sum()), dtype=np.int64))   # ties keep the log order
    return pa.table(data)


def _link_max_latency_s(flow: pa.Table) -> pa.Array:
    """Per row: the largest latency seen on its link (src, dst), in s; 0 for a link with none."""
    per_link = flow.group_by(["src", "dst"]).aggregate([(LAT, "max")]).rename_columns(["src", "dst", "_max"])
    joined = flow.select(["src", "dst", "_row"]).join(per_link, ["src", "dst"], use_threads=False)
    joined = joined.sort_by("_row")   # back to flow's row order (flow is sorted by _row)
    return pc.divide(pc.fill_null(joined["_max"], 0.0), 1e3)


def message_flow(messages: pd.DataFrame, tick_s: float = 0.0) -> pd.DataFrame:
    """One row per (message, destination); see :func:`swarmbox.analysis.network.message_flow`."""
    kind = messages["kind"]
    send = (kind == "send").to_numpy(dtype=bool)
    recv = (kind == "recv").to_numpy(dtype=bool)
    drop = (kind == "drop").to_numpy(dtype=bool)
    flow = _sends(messages, send).join(_first_arrivals(messages, recv), _KEYS, use_threads=False)
    flow = flow.join(_first_drops(messages, drop), _KEYS, use_threads=False).sort_by("_row")
    lat = pc.multiply(pc.subtract(flow["t_recv"], flow["t_send"]), 1e3)
    flow = flow.append_column(LAT, lat)
    delivered = pc.is_valid(flow["t_recv"])
    logged = messages.loc[messages["node"] != NET, "node"].astype("int64").unique()
    t_end = float(messages[T].max()) if len(messages) else np.nan
    margin = tick_s if np.isfinite(tick_s) else 0.0
    limit = pc.subtract(pc.subtract(pa.scalar(t_end), _link_max_latency_s(flow)), margin)
    late = pc.fill_null(pc.greater(flow["t_send"], limit), False)
    in_flight = pc.and_(pc.and_(pc.invert(delivered), pc.is_null(flow["drop_reason"])), late)
    counted = pc.and_(pc.is_in(flow["dst"], pa.array(logged, pa.int64())), pc.invert(in_flight))
    flow = flow.append_column("delivered", delivered).append_column("counted", counted)
    flow = flow.append_column("lost", pc.and_(counted, pc.invert(delivered)))
    keys = [(name, "ascending", "at_end") for name in ("t_send", "msg_id", "dst", "_row")]
    order = pc.sort_indices(flow, sort_keys=keys)   # NaN and null last, as pandas sorts
    flow = flow.take(order).drop_columns("_row")
    # self_destruct: each Arrow column is freed once copied. Not split_blocks: its zero-copy columns
    # would be read-only, and callers may edit the flow they are given.
    out = flow.to_pandas(self_destruct=True)
    del flow
    pa.default_memory_pool().release_unused()   # the join's buffers: give them back, not keep them pooled
    for name in ("type", "drop_reason"):
        out[name] = out[name].astype("str")
    return out
