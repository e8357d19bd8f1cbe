"""The RQ4 numbers the README publishes, as committed data.

``python -m experiments.rq4_delivery.fig4 SWEEP --publish`` copies the sweep's ``summary.csv`` and
``paired.csv`` (delivery algorithms only) into ``experiments/rq4_delivery/results/`` and writes from
them, with this module:

- ``rq4_table.md``: Table 6 (:func:`fig4.results_table`), the README's result table;
- ``rq4_findings.md``: the paired differences the README's findings cite, one row per comparison
  (:data:`FINDINGS`), each with its label (F1a, ...).

``tests/test_published.py`` rebuilds both from the committed CSVs and requires them equal
to the committed markdown, and ``python -m experiments.published --check`` requires the README's
blocks equal to the markdown: a number in the README cannot drift from the data under it.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd

from swarmbox.analysis.tables import to_markdown

RESULTS = Path(__file__).resolve().parent / "results"
DYN, RR, BLK = "dynamic", "rr", "block"


def algo(sort: str, assign: str) -> str:
    return f"delivery_{sort}_{assign}"


#: The comparisons the README's findings cite: label -> (a, b, metric); the table gives b - a.
FINDINGS: dict[str, tuple[str, str, str]] = {
    **{f"F1{k}": (algo("none", a), algo("distance", a), "distance_h_m_mean")
       for k, a in zip("abc", (BLK, RR, DYN), strict=True)},
    **{f"F1{k}": (algo("none", a), algo("distance", a), "mission_duration_s")
       for k, a in zip("def", (BLK, RR, DYN), strict=True)},
    **{f"F1{k}": (algo("none", a), algo("distance", a), "delivery_wait_s_mean")
       for k, a in zip("ghi", (BLK, RR, DYN), strict=True)},
    **{f"F2{k}": (algo("none", a), algo("azimuth", a), "mission_duration_s")
       for k, a in zip("abc", (BLK, RR, DYN), strict=True)},
    **{f"F2{k}": (algo("none", a), algo("azimuth", a), "delivery_wait_s_mean")
       for k, a in zip("def", (BLK, RR, DYN), strict=True)},
    **{f"F3{k}": (algo(s, RR), algo(s, DYN), "mission_duration_s")
       for k, s in zip("abc", ("none", "azimuth", "distance"), strict=True)},
    **{f"F3{k}": (algo(s, BLK), algo(s, DYN), "mission_duration_s")
       for k, s in zip("def", ("none", "azimuth", "distance"), strict=True)},
    "F4a": (algo("none", BLK), algo("distance", BLK), "delivery_wait_s_max"),
    "F4b": (algo("distance", DYN), algo("distance", BLK), "delivery_wait_s_max"),
    **{f"F4{k}": (algo(s, BLK), algo(s, RR), "delivery_wait_s_max")
       for k, s in zip("cde", ("distance", "azimuth", "none"), strict=True)},
    "F5a": (algo("distance", DYN), algo("azimuth", DYN), "mission_duration_s"),
    "F5b": (algo("distance", DYN), algo("azimuth", DYN), "delivery_wait_s_max"),
    "F5c": (algo("distance", DYN), algo("azimuth", DYN), "delivery_wait_s_mean"),
}


def short(name: str) -> str:
    """``delivery_distance_dynamic`` -> ``distance + dynamic``."""
    _, sort, assign = name.split("_")
    return f"{sort} + {assign}"


def lookup(paired: pd.DataFrame, a: str, b: str, metric: str) -> dict:
    """The paired difference b - a of ``metric``, whichever way round the analyzer paired them."""
    rows = paired[paired["metric"] == metric]
    hit = rows[(rows["a"] == a) & (rows["b"] == b)]
    if len(hit) == 1:
        r = hit.iloc[0]
        return {"n_pairs": int(r["n_pairs"]), "diff": r["diff_mean"], "low": r["ci_low"],
                "high": r["ci_high"], "p": r["p_wilcoxon"]}
    hit = rows[(rows["a"] == b) & (rows["b"] == a)]
    if len(hit) != 1:
        raise KeyError(f"paired.csv has no single row for {a} vs {b} on {metric}")
    r = hit.iloc[0]
    return {"n_pairs": int(r["n_pairs"]), "diff": -r["diff_mean"], "low": -r["ci_high"],
            "high": -r["ci_low"], "p": r["p_wilcoxon"]}


def findings_table(paired: pd.DataFrame) -> pd.DataFrame:
    """One row per cited comparison: label, a, b, metric, pairs, mean of b - a [95 % CI], Wilcoxon p."""
    rows = []
    for label, (a, b, metric) in FINDINGS.items():
        d = lookup(paired, a, b, metric)
        rows.append({"label": label, "a": short(a), "b": short(b), "metric": f"`{metric}`",
                     "pairs": d["n_pairs"], "b - a": f"{d['diff']:+.1f} [{d['low']:+.1f}, {d['high']:+.1f}]",
                     "Wilcoxon p": "< 0.001" if d["p"] < 0.001 else f"{d['p']:.3f}"})
    return pd.DataFrame(rows)


def tables_from(results: Path = RESULTS) -> dict[str, str]:
    """The README's markdown tables, rebuilt from the committed CSVs of ``results``: file name -> text."""
    from experiments.rq4_delivery.fig4 import results_table  # fig4 imports this module

    summary = pd.read_csv(results / "summary.csv")
    paired = pd.read_csv(results / "paired.csv")
    return {"rq4_table.md": to_markdown(results_table(summary)),
            "rq4_findings.md": to_markdown(findings_table(paired))}


def write(sweep_tables: Path, results: Path = RESULTS) -> list[Path]:
    """Copy the sweep's summary and paired tables (delivery algorithms) and its pooled package waits
    into ``results``, then write the README's tables from the copies; returns the written paths."""
    results.mkdir(parents=True, exist_ok=True)
    summary = pd.read_csv(sweep_tables / "summary.csv")
    summary[summary["algo"].str.startswith("delivery_")].to_csv(results / "summary.csv", index=False)
    paired = pd.read_csv(sweep_tables / "paired.csv")
    cited = {metric for _, _, metric in FINDINGS.values()}
    paired[paired["metric"].isin(cited)].to_csv(results / "paired.csv", index=False)   # the cited metrics
    shutil.copyfile(sweep_tables / "rq4_package_waits.md", results / "rq4_package_waits.md")
    written = [results / n for n in ("summary.csv", "paired.csv", "rq4_package_waits.md")]
    for name, text in tables_from(results).items():
        (results / name).write_text(text)
        written.append(results / name)
    return written
