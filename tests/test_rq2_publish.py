"""The RQ2 sim-vs-PX4 tables of the documentation are what publish.py computes, exactly: from the
committed PX4 flights and fresh sim and sim_px4 runs (deterministic, six short real runs)."""

import importlib.util
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
HERE = ROOT / "experiments" / "rq2_fidelity"


def test_rq2_tables_rebuild_from_the_committed_flights(tmp_path):
    sys.path.insert(0, str(HERE))
    spec = importlib.util.spec_from_file_location("rq2_publish", HERE / "publish.py")
    publish = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(publish)
    built = publish.tables(publish.fly(tmp_path))
    assert set(built) == {p.stem for p in (HERE / "results").glob("*.csv")}
    for name, frame in built.items():
        committed = pd.read_csv(HERE / "results" / f"{name}.csv", dtype=str, keep_default_na=False)
        pd.testing.assert_frame_equal(frame.astype(str), committed, obj=name)
    # the legs: three PX4 flights per order, four legs each
    for cell in built["legs"]["PX4 SIH flights"]:
        flights = cell.split("; ")
        assert len(flights) == 3 and all(len(f.split(", ")) == 4 for f in flights)
