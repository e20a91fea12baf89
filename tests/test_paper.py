"""Our tables beside the paper's: quoted numbers are read as written, the relative change is ours / paper - 1, and
an ordering is held only when every row beats the next (lower errors, higher PGP)."""

import pandas as pd
import pytest

from refinenet.evaluation.paper import (
    PAPER_COLUMNS,
    PCPNET_COLUMNS,
    QUOTED,
    Ordering,
    comparison_markdown,
    comparison_rows,
)


def frame(rows: dict[str, dict[str, float]], categories=PAPER_COLUMNS) -> pd.DataFrame:
    """Our table with the given cells; the categories' other cells hold 1.0."""
    metrics = {column.split("/")[1] for row in rows.values() for column in row}
    return pd.DataFrame.from_dict({name: {**{f"{c}/{m}": 1.0 for c in categories for m in metrics}, **row}
                                   for name, row in rows.items()}, orient="index")


def test_quoted_rows_are_read_in_the_papers_column_order():
    mfps = QUOTED["table_synthetic"]["MFPS"]
    assert (mfps["BigNoise/mean"], mfps["SmoothSurface/rmse"], mfps["Average/mean"]) == (5.72, 6.32, 4.75)
    assert QUOTED["table_synthetic_pgp"]["Refine-Net"]["Average/pgp10"] == 0.935
    assert len(QUOTED["table_ablation"]) == 10 and all(len(row) == 10 for row in QUOTED["table_ablation"].values())
    assert QUOTED["table_pcpnet"]["Refine-Net"] == {"None/rmse": 6.27, "0.00125/rmse": 9.18, "0.006/rmse": 16.59,
                                                    "0.012/rmse": 22.57, "Gradient/rmse": 6.61,
                                                    "Stripes/rmse": 7.02, "Average/rmse": 11.37}


def test_our_number_beside_the_papers():
    ours = frame({"MFPS": {"Average/mean": 5.225, "Average/rmse": 8.22}, "Jet": {"Average/mean": 1.0}})
    rows = {(r["row"], r["column"]): r for r in comparison_rows("table_synthetic", ours)}
    assert {column for row, column in rows} == {f"{c}/{m}" for c in PAPER_COLUMNS for m in ("mean", "rmse")}
    assert {row for row, column in rows} == {"MFPS"}  # Jet is not in the paper's table
    assert rows[("MFPS", "Average/mean")]["change"] == pytest.approx(0.1)
    assert rows[("MFPS", "Average/rmse")]["change"] == pytest.approx(0.0)


def test_an_average_over_other_categories_is_not_compared():
    """The PCPNet table of the procedural data has the synthetic categories: its Average is not PCPNet's."""
    row = {"MFPS": {"Average/rmse": 12.58}}
    assert comparison_rows("table_pcpnet", frame(row)) == []
    rows = comparison_rows("table_pcpnet", frame(row, PCPNET_COLUMNS))
    assert len(rows) == 7 and rows[-1]["column"] == "Average/rmse" and rows[-1]["change"] == pytest.approx(0.0)


@pytest.mark.parametrize(("column", "values", "held"), [
    ("Average/mean", (1.0, 2.0, 3.0), True),
    ("Average/mean", (1.0, 3.0, 2.0), False),
    ("Average/mean", (1.0, 1.0, 2.0), False),  # a tie does not hold a strict claim
    ("Average/pgp10", (0.9, 0.8, 0.7), True),
    ("Average/pgp10", (0.7, 0.8, 0.9), False),
])
def test_an_ordering_holds_only_when_each_row_beats_the_next(column, values, held):
    ours = frame({row: {column: v} for row, v in zip(("A", "B", "C"), values, strict=True)})
    assert Ordering("t", column, ("A", "B", "C"), "claim").check(ours) == (list(values), held)
    assert Ordering("t", column, ("A", "D"), "claim").check(ours) == (None, None)


def test_the_report_labels_the_papers_numbers_as_quoted():
    ours = {"table_ablation": frame({"MFPS": {"Average/mean": 4.0}, "simple MFPS": {"Average/mean": 5.0}})}
    text = comparison_markdown(ours, "Profile smoke.")
    assert "| MFPS | Average/mean | 4.00 | 4.75 | -16% |" in text
    assert "paper (quoted)" in text and "quoted from the paper" in text
