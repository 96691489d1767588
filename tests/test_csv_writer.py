"""results.write_csv writes the same bytes as pandas' to_csv for the numeric output tables."""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from rce_gtsam.results import write_csv

floats = st.floats(allow_nan=True, allow_infinity=True, width=64)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(-2**62, 2**62), floats, floats), min_size=0, max_size=40))
def test_numeric_table_bytes_equal_pandas(tmp_path_factory, rows):
    df = pd.DataFrame(rows, columns=["frame", "x", "cov_xy"]).astype({"frame": "int64", "x": float, "cov_xy": float})
    d = tmp_path_factory.mktemp("csv")
    write_csv(df, d / "fast.csv")
    df.to_csv(d / "pandas.csv", index=False)
    assert (d / "fast.csv").read_bytes() == (d / "pandas.csv").read_bytes()


def test_tables_with_text_go_through_pandas(tmp_path):
    df = pd.DataFrame({"zone": ["mid", "a,b"], "kappa": [1.5, np.nan]})
    write_csv(df, tmp_path / "t.csv")
    assert (tmp_path / "t.csv").read_text() == df.to_csv(index=False)
