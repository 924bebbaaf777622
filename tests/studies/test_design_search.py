"""The design search (studies.engine.design_search) on planted problems with known answers.

* Single objective: maximise f = -(x-0.3)² - (y-0.7)² - 0.01 (n-3)² + 0.05 [c = "b"] over
  x, y in [0, 1], n in 1..5, c in {a, b, c}: the optimum is x = 0.3, y = 0.7, n = 3, c = "b",
  f* = 0.05. 80 evaluations (seed 0) find n and c exactly and (x, y) within 0.05 (0.010 found).
* Two objectives (Schaffer's problem in two variables): minimise f1 = x² + y² and
  f2 = (x-2)² + y² over x in [-2, 4], y in [-2, 2]. The Pareto set is y = 0, 0 <= x <= 2, the
  front f2 = (2 - √f1)² for f1 in [0, 4]. 120 evaluations (seed 0) give a front every point of
  which lies within 0.25 of the analytic front (0.04 found; objectives span 0-4), half within
  0.02 (0.009 found), with >= 5 distinct points spanning f1 from below 0.1 to above 3.
"""

from __future__ import annotations

import json
import math

import numpy as np
import optuna
import pandas as pd
import pytest
from optuna.storages import JournalStorage
from optuna.storages.journal import JournalFileBackend

from studies.engine.design_search import (
    JOURNAL_NAME,
    Constraint,
    DesignSpace,
    Metric,
    Objective,
    Param,
    Progress,
    choice_param,
    float_param,
    int_param,
    search,
    trial_seed,
    write_results,
)
from tests.helpers.design_search_toys import schaffer

TOY = "planted test problem"

MIXED = DesignSpace(
    (
        float_param("x", 0.0, 1.0, unit="m", assumed=TOY),
        float_param("y", 0.0, 1.0, unit="m", assumed=TOY),
        int_param("n", 1, 5, assumed=TOY),
        choice_param("c", ["a", "b", "c"], assumed=TOY),
    )
)
MIXED_BEST = {"x": 0.3, "y": 0.7, "n": 3, "c": "b"}
MIXED_F_STAR = 0.05

SCHAFFER = DesignSpace((float_param("x", -2.0, 4.0, assumed=TOY), float_param("y", -2.0, 2.0, assumed=TOY)))
BOTH = [("f1", "minimize"), ("f2", "minimize")]


def mixed(design: dict) -> dict:
    x, y, n, c = design["x"], design["y"], design["n"], design["c"]
    return {"f": -((x - 0.3) ** 2) - (y - 0.7) ** 2 - 0.01 * (n - 3) ** 2 + (0.05 if c == "b" else 0.0)}


def front_distances(points: np.ndarray) -> np.ndarray:
    """Distance of each (f1, f2) to Schaffer's analytic front (x = s in [0, 2], y = 0)."""
    s = np.linspace(0.0, 2.0, 4001)
    curve = np.stack([s * s, (2 - s) ** 2], axis=1)
    return np.min(np.linalg.norm(points[:, None, :] - curve[None, :, :], axis=2), axis=1)


class StopAt:
    """``schaffer`` that raises ``exc`` at its ``k``-th call (a search stopped there)."""

    def __init__(self, k: int, exc: BaseException):
        self.k, self.exc, self.calls = k, exc, 0

    def __call__(self, design: dict) -> dict:
        self.calls += 1
        if self.calls == self.k:
            raise self.exc
        return schaffer(design)


def never_called(design: dict) -> dict:
    raise AssertionError("evaluate must not be called")


def run_schaffer(out, trials=30, seed=3, evaluate=schaffer, **kwargs):
    kwargs.setdefault("constraints", [("f1", "<=", 3.0)])
    return search(SCHAFFER, evaluate, BOTH, metrics=["f1", "f2"], trials=trials, seed=seed, out=out, **kwargs)


# --- planted optima -------------------------------------------------------------------------------


def test_single_objective_finds_the_planted_optimum(tmp_path):
    result = search(MIXED, mixed, [("f", "maximize")], metrics=["f"], trials=80, seed=0, out=tmp_path)
    best = result.front[0]
    assert result.evaluations == 80 and result.feasible == 80
    assert best.design["n"] == MIXED_BEST["n"] and best.design["c"] == MIXED_BEST["c"]
    assert math.hypot(best.design["x"] - 0.3, best.design["y"] - 0.7) < 0.05
    assert MIXED_F_STAR - 0.003 < best.metrics["f"] <= MIXED_F_STAR
    assert best.metrics["f"] == result.trials["f"].max()


def test_two_objectives_find_and_span_the_analytic_front(tmp_path):
    result = search(SCHAFFER, schaffer, BOTH, metrics=["f1", "f2"], trials=120, seed=0, out=tmp_path)
    points = np.array([[p.metrics["f1"], p.metrics["f2"]] for p in result.front])
    distances = front_distances(points)
    assert distances.max() < 0.25 and np.median(distances) < 0.02
    assert len({tuple(p) for p in points}) >= 5
    assert points[:, 0].min() < 0.1 and points[:, 0].max() > 3.0
    assert list(points[:, 0]) == sorted(points[:, 0])  # best first by the first objective
    assert result.trials["on_front"].sum() == len(result.front)


# --- constraints ----------------------------------------------------------------------------------


def test_designs_violating_a_constraint_are_never_on_the_front(tmp_path):
    result = run_schaffer(tmp_path, trials=40, constraints=[("f1", ">=", 1.0), Constraint("f2", "<=", 2.0)])
    trials = result.trials
    assert (~trials["feasible"]).sum() > 5  # the constraints bite
    assert trials.loc[~trials["feasible"], "violation"].gt(0).all()
    assert not trials.loc[~trials["feasible"], "on_front"].any()
    assert result.front and all(p.metrics["f1"] >= 1.0 and p.metrics["f2"] <= 2.0 for p in result.front)
    assert result.feasible == trials["feasible"].sum() and result.infeasible == ""


def test_a_constraint_never_met_is_named(tmp_path):
    result = run_schaffer(tmp_path, trials=15, constraints=[("f2", "<=", -1.0), ("f1", "<=", 100.0)])
    assert result.feasible == 0 and result.front == () and result.evaluations == 15
    assert "no design met f2 <= -1" in result.infeasible and "f1 <=" not in result.infeasible
    assert "\n" not in result.infeasible
    summary = json.loads(write_results(result, tmp_path)[2].read_text())
    assert summary["feasible"] == 0 and "f2 <= -1" in summary["infeasible"]


def test_constraints_met_apart_but_never_together(tmp_path):
    result = run_schaffer(tmp_path, trials=30, constraints=[("f1", "<=", 0.9), ("f2", "<=", 0.9)])  # disjoint discs
    assert result.feasible == 0
    assert "no design met all constraints at once" in result.infeasible


def test_a_constraint_outside_its_metrics_bounds_is_infeasible_at_once(tmp_path):
    out = tmp_path / "search"
    metrics = [Metric("f1", low=0.0), Metric("rate", high=1.0)]
    result = search(
        SCHAFFER, never_called, [("f1", "minimize")], [("rate", ">=", 1.5)], metrics=metrics, trials=10, seed=0, out=out
    )
    assert result.feasible == 0 and result.evaluations == 0 and result.front == ()
    assert "no value can meet rate >= 1.5 (rate lies in (-∞, 1])" in result.infeasible
    assert not out.exists()


# --- resume and determinism -----------------------------------------------------------------------


@pytest.mark.parametrize(
    "stop",
    [RuntimeError("simulator crashed"), KeyboardInterrupt(), SystemExit(1)],
    ids=["evaluate-raises", "ctrl-c", "hard-kill"],
)
def test_a_stopped_search_resumed_gives_the_uninterrupted_front(tmp_path, stop):
    whole = run_schaffer(tmp_path / "whole")
    out = tmp_path / "stopped"
    with pytest.raises(type(stop)):
        run_schaffer(out, evaluate=StopAt(12, stop))
    if isinstance(stop, SystemExit):  # a kill: the trial stays RUNNING, a design may be left enqueued, a line cut short
        study = optuna.load_study(
            study_name="design-search", storage=JournalStorage(JournalFileBackend(str(out / JOURNAL_NAME)))
        )
        assert [t.state for t in study.trials].count(optuna.trial.TrialState.RUNNING) == 1
        study.enqueue_trial({"x": 0.0, "y": 0.0}, user_attrs={"index": 12})
        with open(out / JOURNAL_NAME, "ab") as f:
            f.write(b'{"op_code": 5, "worker_id": "cut sho')
    resumed = run_schaffer(out, resume=True)
    assert resumed.evaluated_now == 30 - 11 and resumed.evaluations == 30
    assert resumed.front == whole.front and len(whole.front) >= 3
    pd.testing.assert_frame_equal(resumed.trials, whole.trials)
    write_results(whole, tmp_path / "whole")
    write_results(resumed, out)
    for name in ("front.csv", "trials.csv", "summary.json"):
        assert (out / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()


def test_a_search_run_in_parts_equals_one_run(tmp_path):
    whole = run_schaffer(tmp_path / "whole")
    out = tmp_path / "parts"
    first = run_schaffer(out, trials=10)
    resumed = run_schaffer(out, trials=30, resume=True)
    assert first.evaluated_now == 10 and resumed.evaluated_now == 20
    assert resumed.front == whole.front
    pd.testing.assert_frame_equal(resumed.trials, whole.trials)
    again = run_schaffer(out, trials=10, resume=True)  # the first 10 of the stored 30, nothing evaluated
    assert again.evaluated_now == 0
    columns = [c for c in whole.trials.columns if c != "on_front"]
    pd.testing.assert_frame_equal(again.trials[columns], whole.trials[columns].iloc[:10])


def test_same_seed_same_trials_other_seed_other_trials(tmp_path):
    a = run_schaffer(tmp_path / "a", trials=15, seed=5)
    b = run_schaffer(tmp_path / "b", trials=15, seed=5)
    c = run_schaffer(tmp_path / "c", trials=15, seed=6)
    pd.testing.assert_frame_equal(a.trials, b.trials)
    assert not np.isin(c.trials["x"], a.trials["x"]).any()
    assert trial_seed(5, 0) != trial_seed(6, 0) and trial_seed(5, 0) != trial_seed(5, 1)


def test_parallel_batches_are_deterministic_and_resumable(tmp_path):
    """Two workers: 8 evaluations in one run equal 3 (a batch cut in half) then a resume to 8."""
    whole = run_schaffer(tmp_path / "whole", trials=8, workers=2, constraints=[])
    out = tmp_path / "parts"
    run_schaffer(out, trials=3, workers=2, constraints=[])
    resumed = run_schaffer(out, trials=8, workers=2, constraints=[], resume=True)
    assert resumed.evaluated_now == 5
    pd.testing.assert_frame_equal(resumed.trials, whole.trials)
    with pytest.raises(ValueError, match=r"^resume: search\.workers: stored 2, given 1 "):
        run_schaffer(out, trials=8, constraints=[], resume=True)


# --- the out folder -------------------------------------------------------------------------------


def test_out_holding_a_search_needs_resume_and_the_same_definition(tmp_path):
    run_schaffer(tmp_path, trials=3)
    with pytest.raises(FileExistsError, match="holds a search already") as info:
        run_schaffer(tmp_path, trials=3)
    assert "\n" not in str(info.value)
    wider = DesignSpace((float_param("x", -2.0, 5.0, assumed=TOY), SCHAFFER.params[1]))
    cases = [
        (dict(seed=4), r"search\.seed: stored 3, given 4"),
        (dict(constraints=[("f1", "<=", 2.0)]), r"search\.constraints\[0\]\.bound: stored 3\.0, given 2\.0"),
        (dict(context={"frames": 4}), r"search\.context: stored null, given \{\"frames\": 4\}"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ValueError, match=rf"^resume: {message} "):
            run_schaffer(tmp_path, trials=3, resume=True, **kwargs)
    with pytest.raises(ValueError, match=r"^resume: search\.space\.x\.high: stored 4\.0, given 5\.0 "):
        search(
            wider,
            schaffer,
            BOTH,
            [("f1", "<=", 3.0)],
            metrics=["f1", "f2"],
            trials=3,
            seed=3,
            out=tmp_path,
            resume=True,
        )
    with pytest.raises(ValueError, match=r"^resume: search\.objectives\[1\]\.direction: stored \"minimize\""):
        objectives = [("f1", "minimize"), ("f2", "maximize")]
        search(
            SCHAFFER,
            schaffer,
            objectives,
            [("f1", "<=", 3.0)],
            metrics=["f1", "f2"],
            trials=3,
            seed=3,
            out=tmp_path,
            resume=True,
        )


def test_write_results_writes_parseable_files_atomically(tmp_path):
    result = run_schaffer(tmp_path, trials=12, constraints=[("f1", "<=", 0.5)])
    paths = write_results(result, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["front.csv", JOURNAL_NAME, "summary.json", "trials.csv"]

    def no_constant(name):
        raise ValueError(f"non-standard JSON constant {name}")

    summary = json.loads(paths[2].read_text(), parse_constant=no_constant)
    assert summary["seed"] == 3 and summary["evaluations"] == 12 and summary["requested"] == 12
    assert summary["feasible"] == result.feasible and summary["front_size"] == len(result.front)
    assert summary["front"] == [p.to_dict() for p in result.front]
    assert summary["constraints"] == [{"metric": "f1", "op": "<=", "bound": 0.5}]
    front = pd.read_csv(paths[0])
    trials = pd.read_csv(paths[1])
    assert list(front["trial"]) == [p.trial for p in result.front]
    assert list(trials.columns) == ["trial", "x", "y", "f1", "f2", "feasible", "violation", "status", "on_front"]
    assert np.array_equal(trials["x"].to_numpy(), result.trials["x"].to_numpy())  # floats round-trip exactly


# --- evaluations and progress ---------------------------------------------------------------------


def sometimes_nan(design: dict) -> dict:
    metrics = schaffer(design)
    return {**metrics, "f2": math.nan} if design["x"] > 2.5 else metrics


def test_non_finite_objectives_are_evaluations_but_never_feasible(tmp_path):
    result = run_schaffer(tmp_path / "whole", trials=20, evaluate=sometimes_nan, constraints=[])
    bad = result.trials["status"] == "non-finite"
    assert bad.any() and (result.trials.loc[bad, "x"] > 2.5).all()
    assert not result.trials.loc[bad, "feasible"].any() and result.non_finite == bad.sum()
    assert result.evaluations == 20 and all(math.isfinite(p.metrics["f2"]) for p in result.front)
    run_schaffer(tmp_path / "parts", trials=8, evaluate=sometimes_nan, constraints=[])
    again = run_schaffer(tmp_path / "parts", trials=20, evaluate=sometimes_nan, constraints=[], resume=True)
    pd.testing.assert_frame_equal(again.trials, result.trials)  # NaN comes back from the journal


def test_an_evaluate_returning_other_metrics_stops_with_the_metric_named(tmp_path):
    with pytest.raises(ValueError, match=r"^evaluate: trial 0: returned no 'f2' \(declared: f1, f2\)$"):
        run_schaffer(tmp_path / "a", evaluate=lambda d: {"f1": 1.0})
    with pytest.raises(ValueError, match=r"^evaluate: trial 0: returned an undeclared metric 'f3'"):
        run_schaffer(tmp_path / "b", evaluate=lambda d: {**schaffer(d), "f3": 1.0})
    with pytest.raises(ValueError, match=r"^evaluate: trial 0: f1 = 2\.0 is outside its declared bounds \[0, 1\]"):
        search(
            SCHAFFER,
            lambda d: {"f1": 2.0},
            [("f1", "minimize")],
            metrics=[Metric("f1", low=0, high=1)],
            trials=2,
            seed=0,
            out=tmp_path / "c",
        )
    resumed = run_schaffer(tmp_path / "a", trials=5, resume=True)  # the failed trial is redone
    assert resumed.evaluations == 5 and resumed.evaluated_now == 5


def test_progress_counts_up_and_starts_from_the_stored_evaluations(tmp_path):
    seen: list[Progress] = []
    run_schaffer(tmp_path, trials=6, progress=seen.append)
    assert [p.done for p in seen] == list(range(7)) and {p.total for p in seen} == {6}
    assert seen[0].best == {} and set(seen[-1].best) == {"f1", "f2"}
    best_f1 = [p.best["f1"] for p in seen if p.best]
    assert best_f1 == sorted(best_f1, reverse=True)  # the best so far only improves
    resumed: list[Progress] = []
    run_schaffer(tmp_path, trials=8, progress=resumed.append, resume=True)
    assert [p.done for p in resumed] == [6, 7, 8] and resumed[0].feasible == seen[-1].feasible


# --- bad input: one line naming the field, before anything is evaluated or written ----------------


def from_dict_missing_high():
    return DesignSpace.from_dict({"offset_mm": {"kind": "float", "low": 2, "unit": "mm", "source": "drawing"}})


BAD = [
    (
        lambda: dict(space=DesignSpace((float_param("offset_mm", 50, 20, assumed=TOY),))),
        r"space\.offset_mm\.low: expected a number < high, got 50\.0 >= 20\.0",
    ),
    (lambda: dict(space=from_dict_missing_high()), r"space\.offset_mm\.high: missing"),
    (
        lambda: dict(space=DesignSpace.from_dict({"x": {"kind": "float", "low": 0, "hihg": 1, "assumed": TOY}})),
        r"space\.x\.hihg: unknown key .*did you mean 'high'\?",
    ),
    (
        lambda: dict(space=DesignSpace.from_dict({"x": {"low": 0, "high": 1, "assumed": TOY}})),
        r"space\.x\.kind: missing",
    ),
    (
        lambda: dict(space=DesignSpace((choice_param("led", ["red"], assumed=TOY),))),
        r"space\.led\.values: expected at least 2 values, got 1",
    ),
    (
        lambda: dict(space=DesignSpace((choice_param("led", ["red", "red"], assumed=TOY),))),
        r"space\.led\.values\[1\]: 'red' is listed twice",
    ),
    (
        lambda: dict(space=DesignSpace((float_param("x", 0, 1),))),
        r"space\.x: needs exactly one of 'source' or 'assumed'",
    ),
    (
        lambda: dict(space=DesignSpace((float_param("x", 0, 1, log=True, assumed=TOY),))),
        r"space\.x\.low: a log-scale parameter needs low > 0",
    ),
    (
        lambda: dict(space=DesignSpace((int_param("n", 1, 2.5, assumed=TOY),))),
        r"space\.n\.high: expected an integer, got 2\.5",
    ),
    (
        lambda: dict(space=DesignSpace((Param("x", "real", 0, 1, assumed=TOY),))),
        r"space\.x\.kind: expected one of 'float', 'int', 'choice'",
    ),
    (lambda: dict(space=DesignSpace((SCHAFFER.params[0], SCHAFFER.params[0]))), r"space\.x: defined twice"),
    (
        lambda: dict(objectives=[("f3", "minimize")]),
        r"objectives\[0\]\.metric: unknown metric 'f3' \(declared: f1, f2\)",
    ),
    (
        lambda: dict(objectives=[("f1", "minimize"), ("f2", "min")]),
        r"objectives\[1\]\.direction: expected one of 'maximize', 'minimize'.*got 'min'",
    ),
    (
        lambda: dict(objectives=[Objective("f1", "minimize"), ("f1", "maximize")]),
        r"objectives\[1\]\.metric: 'f1' is already an objective",
    ),
    (lambda: dict(objectives=[]), r"objectives: expected at least one objective"),
    (lambda: dict(objectives=[("f1",)]), r"objectives\[0\]: expected \(metric, direction\)"),
    (lambda: dict(constraints=[("f1", "<", 1.0)]), r"constraints\[0\]\.op: expected one of '<=', '>='.*got '<'"),
    (lambda: dict(constraints=[("f1", "<=", math.nan)]), r"constraints\[0\]\.bound: expected a finite number, got nan"),
    (lambda: dict(constraints=[("g", ">=", 1.0)]), r"constraints\[0\]\.metric: unknown metric 'g'"),
    (lambda: dict(metrics=["f1", "f2", "x"]), r"metrics\.x: also the name of a design parameter"),
    (
        lambda: dict(metrics=["f1", "f2", "feasible"]),
        r"metrics: metric name: 'feasible' is a column of the trials table",
    ),
    (lambda: dict(metrics=[Metric("f1", low=1, high=0), "f2"]), r"metrics\.f1\.low: expected a number < high"),
    (lambda: dict(trials=0), r"trials: expected an integer >= 1, got 0"),
    (lambda: dict(seed=-1), r"seed: expected an integer >= 0, got -1"),
    (lambda: dict(workers=1.5), r"workers: expected an integer >= 1, got 1\.5"),
    (lambda: dict(context={"f": math.inf}), r"context: expected JSON-able values"),
]


@pytest.mark.parametrize("bad, message", BAD, ids=[f"bad{i}" for i in range(len(BAD))])
def test_bad_input_is_one_line_naming_the_field_before_any_work(tmp_path, bad, message):
    out = tmp_path / "search"
    args = dict(
        space=SCHAFFER, objectives=BOTH, constraints=[("f1", "<=", 3.0)], metrics=["f1", "f2"], trials=5, seed=0
    )
    with pytest.raises(ValueError, match=rf"^{message}") as info:
        args.update(bad())
        search(args.pop("space"), never_called, args.pop("objectives"), args.pop("constraints"), out=out, **args)
    assert "\n" not in str(info.value)
    assert not out.exists()


def test_a_space_round_trips_through_its_tables():
    assert DesignSpace.from_dict(MIXED.to_dict()) == MIXED
    assert MIXED.names == ("x", "y", "n", "c") and MIXED.params[0].reason == f"assumed: {TOY}"
    assert MIXED.params[0].describe() == "x in [0, 1] m"
