"""Result tables: results.parquet / results.csv (one row per frame × detector) and the
detection curves drawn from them."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from scenes.render_cache import atomic_write_bytes
from studies.engine.metrics import jeffreys_interval, wilson_intervals
from studies.engine.scoring import detection_successes, failure_cause, pose_success

__all__ = ["CSV_MAX_ROWS", "detection_curve", "parquet_bytes", "pose_outcomes", "write_tables"]

CSV_MAX_ROWS = 1_000_000
"""Above this many rows only results.parquet is written (a CSV would take gigabytes)."""


def write_tables(out: Path, rows) -> object:
    """results.parquet and, up to :data:`CSV_MAX_ROWS` rows, results.csv (one row per
    frame × detector) from row dicts or a DataFrame; returns the DataFrame."""
    frame = rows if isinstance(rows, pd.DataFrame) else pd.DataFrame(rows)
    Path(out).mkdir(parents=True, exist_ok=True)
    csv_path = Path(out) / "results.csv"
    if len(frame) <= CSV_MAX_ROWS:
        atomic_write_bytes(csv_path, frame.to_csv(index=False, float_format="%.9g").encode())
    else:
        csv_path.unlink(missing_ok=True)  # never leave an earlier run's table beside this one
    atomic_write_bytes(Path(out) / "results.parquet", parquet_bytes(frame))
    return frame


def parquet_bytes(frame) -> bytes:
    """A DataFrame as Parquet file bytes (no index)."""
    buf = io.BytesIO()
    frame.to_parquet(buf, index=False)
    return buf.getvalue()


def detection_curve(frame, by: Sequence[str], x: str = "nominal_range_m"):
    """Per group and x: ``frames``, ``successes`` (detection successes,
    :func:`studies.engine.scoring.detection_success`: right side, five markers correctly
    numbered; not the results' ``detected`` column, which is "five markers returned") and
    ``p_detect`` = successes / frames with its Wilson 95 % interval (``p_low``, ``p_high``)."""
    keys = [*by, x]
    success = pd.Series(detection_successes(frame), index=frame.index)
    counts = success.groupby([frame[k] for k in keys], sort=True).agg(["size", "sum"])
    table = counts.reset_index().rename(columns={"size": "frames", "sum": "successes"})
    table["frames"] = table["frames"].astype(int)
    table["successes"] = table["successes"].astype(int)
    table["p_detect"], table["p_low"], table["p_high"] = wilson_intervals(table["successes"], table["frames"])
    return table[[*keys, "frames", "successes", "p_detect", "p_low", "p_high"]]


def pose_outcomes(frame, by: Sequence[str], x: str = "nominal_range_m"):
    """Per group and x: frames, pose successes (:func:`studies.engine.scoring.pose_success`)
    and their fraction, the Beta posterior of P(success) under Jeffreys' prior (mean and 95 % credible
    interval, :func:`studies.engine.metrics.jeffreys_interval`) and the most common
    failure cause with its count ("" where no frame failed).

    Parameters
    ----------
    frame : results table (one row per frame and detector; cut it to one detector first).
    by : grouping columns.
    x : the column along which the outcomes are counted (nominal range, m, by default).

    Returns
    -------
    DataFrame with columns ``[*by, x, "frames", "correct", "fraction", "p_mean", "p_low",
    "p_high", "failed", "cause", "cause_frames"]``.
    """
    keys = [*by, x]
    rows = []
    for key, g in frame.groupby(keys, sort=True):
        recs = g.to_dict("records")
        ok = [pose_success(r) for r in recs]
        causes = pd.Series([failure_cause(r) for r, good in zip(recs, ok, strict=True) if not good], dtype=object)
        top = causes.value_counts()
        rows.append(
            {
                **dict(zip(keys, key if isinstance(key, tuple) else (key,), strict=True)),
                "frames": len(recs),
                "correct": int(sum(ok)),
                "failed": len(recs) - int(sum(ok)),
                "cause": str(top.index[0]) if len(top) else "",
                "cause_frames": int(top.iloc[0]) if len(top) else 0,
            }
        )
    table = pd.DataFrame(rows, columns=[*keys, "frames", "correct", "failed", "cause", "cause_frames"])
    table["fraction"] = table["correct"] / table["frames"]
    table["p_mean"], table["p_low"], table["p_high"] = jeffreys_interval(table["correct"], table["frames"])
    columns = ["frames", "correct", "fraction", "p_mean", "p_low", "p_high", "failed", "cause", "cause_frames"]
    return table[[*keys, *columns]]
