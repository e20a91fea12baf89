"""Table time from job benchmark files: seconds per 1k points weigh each job by its cloud's size, and a missing or
malformed benchmark file is reported by its path."""

import json

import pandas as pd
import pytest

from refinenet.errors import InputError
from refinenet.pipeline.timing import PER_1K, TOTAL, job_rows, read_benchmark, time_table, write_time_table

HEADER = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"


def _bench(path, seconds, rss=100.0):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(HEADER + f"{seconds}\t0:00:01\t{rss}\t1\t1\t1\t0\t0\t1\t1\n")


def test_seconds_per_1k_points_weigh_jobs_by_their_clouds(tmp_path):
    """Clouds of 1,000 and 3,000 points, of which b's 1,000 are scored (a PCPNet .pidx): MFPS 1 s and 5 s on every
    point (6 s for 4k points: 1.5 s per 1k), features 2 s each on the scored 2k points (2.0), the network 4 s each
    (4.0); 7.5 s per 1k points in total; 4 clusters of 1,000 parameters."""
    seconds = {"mfps": (1, 5), "features/full": (2, 2), "inference/full": (4, 4)}
    for step, pair in seconds.items():
        for cloud, s in zip(("a", "b"), pair, strict=True):
            _bench(tmp_path / step / f"{cloud}.benchmark.tsv", s)
    jobs = job_rows([("a", 1000, 1000, 1000), ("b", 3000, 1000, 1000)],
                    str(tmp_path / "{step}" / "{cloud}.benchmark.tsv"))
    assert len(jobs) == 6 and set(jobs["rss_mb"]) == {100.0}
    table = time_table(jobs, per_cluster=1000, n_clusters=4)
    assert table[PER_1K].to_dict() == pytest.approx({"MFPS": 1.5, "feature cache": 2.0, "network": 4.0, TOTAL: 7.5})
    assert table.loc[TOTAL, "jobs"] == 6 and table.loc[TOTAL, "parameters"] == 4000
    assert pd.isna(table.loc["MFPS", "parameters"])
    paths = {kind: str(tmp_path / f"out.{kind}") for kind in ("csv", "tex", "per_cloud", "metrics")}
    write_time_table(jobs, table, "caption", "table_time", paths)
    assert json.loads((tmp_path / "out.metrics").read_text()) == {
        PER_1K: {"MFPS": 1.5, "feature cache": 2.0, "network": 4.0, TOTAL: 7.5}, "parameters": 4000}
    assert "Refine-Net in total & 7.500 & 6 & 1,000 & 4,000" in (tmp_path / "out.tex").read_text()


def test_a_missing_or_malformed_benchmark_is_named(tmp_path):
    with pytest.raises(InputError, match=r"absent\.tsv: job benchmark file not found"):
        read_benchmark(tmp_path / "absent.tsv")
    bad = tmp_path / "bad.tsv"
    bad.write_text("s\n")
    with pytest.raises(InputError, match=r"bad\.tsv: not a Snakemake benchmark file"):
        read_benchmark(bad)
