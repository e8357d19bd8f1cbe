"""Published tables are data: every document agrees with the committed files its tables come from.

``experiments/published.py`` checks the real documents (the test that fails when a README and its
data disagree); the other tests pin what it catches on small documents written here.
"""

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from experiments import published
from experiments.rq4_delivery import publish
from swarmbox.analysis.compare import compare, has_regression, load_config, load_summary
from swarmbox.analysis.tables import to_markdown

ROOT = Path(__file__).resolve().parents[1]
TABLE = "| a | b |\n|---|---|\n| x | 1.5 |\n"


def doc(root: Path, text: str, name: str = "README.md") -> Path:
    path = root / name
    path.write_text(text)
    return path


def test_every_document_agrees_with_its_data():
    """The repository's own README, docs and experiment READMEs: no stale block, no unmarked table."""
    problems = [p for path in published.documents() for p in published.check_document(path)]
    assert [str(p) for p in problems] == []


def test_a_changed_number_in_the_data_makes_the_block_stale_and_write_fixes_it(tmp_path):
    (tmp_path / "t.md").write_text(TABLE)
    path = doc(tmp_path, f"text\n<!-- generated: t.md -->\n{TABLE}<!-- /generated -->\nmore\n")
    assert published.check_document(path, tmp_path) == []
    (tmp_path / "t.md").write_text(TABLE.replace("1.5", "1.6"))
    [problem] = published.check_document(path, tmp_path)
    assert "stale" in problem.message and problem.line == 2
    assert published.write_document(path, tmp_path)
    assert "| x | 1.6 |" in path.read_text() and published.check_document(path, tmp_path) == []
    assert path.read_text().endswith("<!-- /generated -->\nmore\n")
    assert not published.write_document(path, tmp_path)      # nothing left to rewrite


def test_a_block_inside_a_list_keeps_its_indent(tmp_path):
    (tmp_path / "t.md").write_text(TABLE)
    path = doc(tmp_path, "1. item\n   <!-- generated: t.md -->\n   <!-- /generated -->\n")
    published.write_document(path, tmp_path)
    assert "   | x | 1.5 |\n" in path.read_text()
    assert published.check_document(path, tmp_path) == []


def test_a_csv_source_renders_its_cells_as_written(tmp_path):
    pd.DataFrame({"fault": ["drift"], "rate": ["0.50"]}).to_csv(tmp_path / "t.csv", index=False)
    assert published.render(tmp_path / "t.csv") == "| fault | rate |\n|---|---|\n| drift | 0.50 |"


def test_an_unmarked_table_of_numbers_fails_and_a_reason_exempts_it(tmp_path):
    path = doc(tmp_path, f"# t\n\n{TABLE}")
    [problem] = published.check_document(path, tmp_path)
    assert problem.line == 3 and "neither generated" in problem.message
    for kind in ("not results", "measured", "pending data"):
        doc(tmp_path, f"# t\n<!-- {kind}: why -->\n\n{TABLE}")
        assert published.check_document(path, tmp_path) == []
    doc(tmp_path, f"# t\n<!-- not results: -->\n{TABLE}")        # a marker needs its reason
    assert len(published.check_document(path, tmp_path)) == 1


def test_digits_in_code_or_in_the_header_only_are_not_numbers(tmp_path):
    path = doc(tmp_path, "| rq4 | x |\n|---|---|\n| `rq4_ci` | `seed=range(20)` |\n")
    assert published.check_document(path, tmp_path) == []


def test_pending_tables_are_listed(tmp_path):
    path = doc(tmp_path, f"<!-- pending data: no data file yet -->\n{TABLE}")
    pending: list = []
    assert published.check_document(path, tmp_path, pending=pending) == []
    assert [p.line for p in pending] == [2]


@pytest.mark.parametrize("text, cause", [
    ("<!-- generated: t.md -->\n| a |\n", "never closed"),
    ("<!-- /generated -->\n", "without an opening"),
    ("<!-- generated: missing.md -->\n<!-- /generated -->\n", "not found"),
])
def test_bad_markers_are_refused(tmp_path, text, cause):
    (tmp_path / "t.md").write_text(TABLE)
    with pytest.raises(published.PublishedError, match=cause):
        published.check_document(doc(tmp_path, text), tmp_path)


def test_the_command_checks_the_repository():
    done = subprocess.run([sys.executable, "-m", "experiments.published", "--check"], cwd=ROOT,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def test_rq4_tables_rebuild_from_the_committed_data():
    """rq4_table.md and rq4_findings.md are what fig4/publish make of the committed CSVs, exactly."""
    for name, text in publish.tables_from().items():
        assert (publish.RESULTS / name).read_text() == text, name


def test_rq4_findings_read_a_pair_either_way_round():
    paired = pd.DataFrame([{"a": "x", "b": "y", "metric": "m", "n_pairs": 20, "diff_mean": 2.0,
                            "ci_low": 1.0, "ci_high": 3.0, "p_wilcoxon": 0.01}])
    assert publish.lookup(paired, "y", "x", "m") == {"n_pairs": 20, "diff": -2.0, "low": -3.0,
                                                      "high": -1.0, "p": 0.01}


def test_rq4_gate_catches_a_move_far_below_five_percent():
    """The CI baseline against itself passes; any deterministic metric moved by 1 ppm fails, whatever
    its built-in tolerance; machine figures are not gated."""
    base_dir = ROOT / "results" / "baselines" / "rq4_ci"
    baseline = load_summary(base_dir / "summary.csv")
    config = load_config(base_dir / "tolerances.yaml")
    assert not has_regression(compare(baseline, baseline.copy(), config))
    machine = {"wall_time_s", "real_time_factor"}
    for metric in sorted(set(baseline["metric"]) - machine):
        moved = baseline.copy()
        rows = moved["metric"] == metric
        value = moved.loc[rows, "value"]
        moved.loc[rows, "value"] = value + np.maximum(np.abs(value) * 1e-6, 1e-9)   # 1 ppm
        verdicts = compare(baseline, moved, config)
        assert set(verdicts[verdicts["metric"] == metric]["verdict"]) - {"ok"}, metric
    moved = baseline.copy()
    moved.loc[moved["metric"].isin(machine), "value"] *= 3
    assert not has_regression(compare(baseline, moved, config))


def test_rq3_bench_tables_rebuild_from_the_committed_rows():
    """Every table of bench/ is what report.py makes of bench/bench_runs.csv, exactly; every count
    in them carries its interval."""
    report = rq3_report()
    bench = ROOT / "experiments" / "rq3_faults" / "bench"
    rows = report.read_rows(bench / "bench_runs.csv")
    for name, table in report.bench_tables_of(rows).items():
        assert (bench / f"{name}.md").read_text() == to_markdown(table), name
    text = (bench / "detection_default.md").read_text()
    assert "/36 [" in text and "/35 " not in text


def rq3_report():
    script = ROOT / "experiments" / "rq3_faults" / "report.py"
    spec = importlib.util.spec_from_file_location("rq3_report", script)
    report = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(report)
    return report


def test_rq3_study_tables_rebuild_from_the_committed_rows():
    """Paper Tables 2, 4, 5 and the totals are what report.py makes of tables/rq3_runs.csv and the
    transcribed paper values, exactly; each count carries its interval."""
    report = rq3_report()
    tables = ROOT / "experiments" / "rq3_faults" / "tables"
    rows = report.read_rows(tables / "rq3_runs.csv")
    summary = report.summarize(rows)
    built = {"rq3_totals": report.totals(rows), "rq3_table2": report.table2(summary),
             "rq3_table4": report.network_table(summary, "latency"),
             "rq3_table5": report.network_table(summary, "packet_loss")}
    for name, table in built.items():
        assert (tables / f"{name}.md").read_text() == to_markdown(table), name
    assert "135/135 [97 %, 100 %]" in to_markdown(built["rq3_totals"])
