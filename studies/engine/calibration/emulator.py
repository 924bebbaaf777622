"""Gaussian-process emulators of one simulator output, and their diagnostics.

An emulator is scikit-learn's :class:`~sklearn.gaussian_process.GaussianProcessRegressor` on the
features of :class:`~studies.engine.calibration.inputs.InputSpace` (the unit cube, log scale where
an input is log-uniform, categoricals one-hot) with the output standardised (zero mean, unit
variance: a constant prior mean), and the kernel

    k(x, x') = σ² · ARD(x, x') + τ² · δ(x, x')

with an ARD Matérn-5/2 (or RBF) correlation and a white-noise term τ² for the simulator's own
randomness (its frames carry sensor noise, so two runs at one input differ). Hyperparameters are
maximum-likelihood, from seeded optimiser restarts (``random_state``), so a seed gives the same
emulator. The fitted record keeps only the training data and the kernel's log-hyperparameters;
the regressor is rebuilt from them with the optimiser off, so an emulator read back from JSON
predicts exactly what the fitted one did.

Diagnostics (Bastos & O'Hagan 2009, "Diagnostics for Gaussian process emulators"): leave-one-out
predictions by the **exact** closed form for a GP with fixed hyperparameters (Rasmussen & Williams
2006, "Gaussian Processes for Machine Learning", §5.4.2: μ₋ᵢ = yᵢ − [K⁻¹y]ᵢ / [K⁻¹]ᵢᵢ,
σ²₋ᵢ = 1 / [K⁻¹]ᵢᵢ), not refits: the hyperparameters and the standardisation are those fitted on
all runs, a small optimism the coverage check would show. Both LOO and held-out validation predict
a new *run* (latent mean plus τ²), the quantity a simulator output is drawn from.

Linear algebra runs on one BLAS thread (:func:`threadpoolctl.threadpool_limits`): the matrices are
tens to hundreds of runs across, where threads cost more than they give (on a loaded 2-core
machine a wave's fits took ten times longer with OpenBLAS's threads); results do not change.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.linalg import cho_solve
from scipy.stats import norm
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Kernel, Matern, WhiteKernel
from threadpoolctl import threadpool_limits

__all__ = ["KERNELS", "Diagnostics", "Emulator", "diagnose", "fit_emulator", "loo", "predict"]

KERNELS = ("matern52", "rbf")
LENGTH_SCALE_BOUNDS = (1e-2, 1e2)
"""Length scales in unit-cube features: from 1 % of a range to far beyond it (an inactive input)."""
NOISE_BOUNDS = (1e-8, 1.0)
"""White-noise variance relative to the output's variance."""
_JITTER = 1e-10


def _kernel(kind: str, n_features: int) -> Kernel:
    if kind not in KERNELS:
        raise ValueError(f"kernel: expected one of {', '.join(KERNELS)}, got {kind!r}")
    # start where the runs are correlated: in p unit-cube features two random points lie ~√(p/6)
    # apart, so a length of 0.3 would leave every run uncorrelated with every other in a wide space
    # (K ≈ I: a flat likelihood the optimiser never leaves); 0.3·√p keeps the start informative
    scales = np.full(n_features, 0.3 * np.sqrt(n_features))
    corr = (
        Matern(length_scale=scales, length_scale_bounds=LENGTH_SCALE_BOUNDS, nu=2.5)
        if kind == "matern52"
        else RBF(length_scale=scales, length_scale_bounds=LENGTH_SCALE_BOUNDS)
    )
    return ConstantKernel(1.0, (1e-3, 1e3)) * corr + WhiteKernel(1e-3, NOISE_BOUNDS)


@dataclass(frozen=True, eq=False)
class Emulator:
    """A fitted emulator of one output.

    Attributes
    ----------
    output
        The output's name.
    kernel
        ``matern52`` or ``rbf``.
    features
        Training features (n, p): unit-cube coordinates, categoricals one-hot.
    y
        Training outputs (n,), in the output's unit (failed runs left out).
    theta
        The kernel's fitted log-hyperparameters (scikit-learn's ``kernel_.theta``): log σ², the p
        log length scales, log τ² (variances relative to the output's variance).
    y_mean, y_std
        The standardisation (output unit).
    log_marginal_likelihood
        At ``theta``, on the standardised outputs.
    fit_warnings
        Optimiser warnings (a hyperparameter at its bound, a line search that stopped).
    """

    output: str
    kernel: str
    features: np.ndarray
    y: np.ndarray
    theta: tuple[float, ...]
    y_mean: float
    y_std: float
    log_marginal_likelihood: float
    fit_warnings: tuple[str, ...] = ()
    gp: GaussianProcessRegressor = field(repr=False, compare=False, default=None)

    @property
    def length_scales(self) -> np.ndarray:
        """ARD length scales in unit-cube features (large: the output hardly depends on that feature)."""
        return np.exp(np.asarray(self.theta[1:-1]))

    @property
    def noise_var(self) -> float:
        """The simulator's own run-to-run variance τ², in the output's unit squared."""
        return float(np.exp(self.theta[-1]) * self.y_std**2)

    def to_json(self) -> dict:
        """The record as JSON-able values (the regressor is rebuilt on reading)."""
        return {
            "output": self.output,
            "kernel": self.kernel,
            "features": self.features.tolist(),
            "y": self.y.tolist(),
            "theta": list(self.theta),
            "y_mean": self.y_mean,
            "y_std": self.y_std,
            "log_marginal_likelihood": self.log_marginal_likelihood,
            "fit_warnings": list(self.fit_warnings),
        }

    @staticmethod
    def from_json(d: dict) -> Emulator:
        """The emulator from :meth:`to_json`'s values, its regressor rebuilt (same predictions)."""
        return _build(
            d["output"],
            d["kernel"],
            np.asarray(d["features"], dtype=float).reshape(len(d["y"]), -1),
            np.asarray(d["y"], dtype=float),
            tuple(float(t) for t in d["theta"]),
            float(d["y_mean"]),
            float(d["y_std"]),
            tuple(d["fit_warnings"]),
        )


def _build(
    output: str,
    kind: str,
    features: np.ndarray,
    y: np.ndarray,
    theta: tuple[float, ...],
    y_mean: float,
    y_std: float,
    fit_warnings: tuple[str, ...],
) -> Emulator:
    kernel = _kernel(kind, features.shape[1]).clone_with_theta(np.asarray(theta))
    gp = GaussianProcessRegressor(kernel=kernel, optimizer=None, alpha=_JITTER, normalize_y=False, copy_X_train=True)
    with threadpool_limits(limits=1, user_api="blas"):
        gp.fit(features, (y - y_mean) / y_std)
    return Emulator(
        output=output,
        kernel=kind,
        features=features,
        y=y,
        theta=theta,
        y_mean=y_mean,
        y_std=y_std,
        log_marginal_likelihood=float(gp.log_marginal_likelihood_value_),
        fit_warnings=fit_warnings,
        gp=gp,
    )


def fit_emulator(
    features: np.ndarray,
    y: np.ndarray,
    *,
    output: str = "",
    kernel: Literal["matern52", "rbf"] = "matern52",
    n_restarts: int = 4,
    seed: int = 0,
) -> Emulator:
    """Fit an emulator of one output by maximum likelihood.

    Parameters
    ----------
    features
        (n, p) emulator features of the runs (:meth:`InputSpace.features`).
    y
        (n,) the output of each run, in its unit; NaN (a failed run) is left out.
    output
        The output's name.
    kernel
        ARD ``matern52`` (default: smooth but not analytic, robust to kinks) or ``rbf``.
    n_restarts
        Optimiser restarts from hyperparameters drawn log-uniformly within their bounds.
    seed
        Seed of the restarts: the same seed gives the same emulator.

    Returns
    -------
    Emulator
    """
    features = np.asarray(features, dtype=float)
    y = np.asarray(y, dtype=float)
    ok = np.isfinite(y)
    if ok.sum() < 3:
        raise ValueError(f"{output}: only {int(ok.sum())} finished runs; an emulator needs at least 3")
    x, y = features[ok], y[ok]
    y_mean = float(np.mean(y))
    y_std = float(np.std(y))
    if not y_std > 0:
        y_std = 1.0  # a constant output: the GP learns a tiny signal variance
    gp = GaussianProcessRegressor(
        kernel=_kernel(kernel, x.shape[1]),
        alpha=_JITTER,
        normalize_y=False,
        n_restarts_optimizer=n_restarts,
        random_state=np.random.RandomState(seed),
    )
    with warnings.catch_warnings(record=True) as caught, threadpool_limits(limits=1, user_api="blas"):
        warnings.simplefilter("always", ConvergenceWarning)
        gp.fit(x, (y - y_mean) / y_std)
    messages = tuple(sorted({str(w.message).splitlines()[0] for w in caught if issubclass(w.category, Warning)}))
    return _build(output, kernel, x, y, tuple(float(t) for t in gp.kernel_.theta), y_mean, y_std, messages)


def predict(emulator: Emulator, features: np.ndarray, *, include_noise: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Emulator mean and variance at ``features``.

    Parameters
    ----------
    include_noise
        True: the variance of a new simulator *run* (the emulator's uncertainty about the mean
        plus the run-to-run variance τ²); False: of the mean alone.

    Returns
    -------
    mean, var
        (n,) each, in the output's unit and unit squared.
    """
    features = np.atleast_2d(np.asarray(features, dtype=float))
    with threadpool_limits(limits=1, user_api="blas"):
        mean_s, std_s = emulator.gp.predict(features, return_std=True)  # std includes the white term
    var = std_s**2 * emulator.y_std**2
    if not include_noise:
        var = np.maximum(var - emulator.noise_var, 0.0)
    return mean_s * emulator.y_std + emulator.y_mean, var


def loo(emulator: Emulator) -> tuple[np.ndarray, np.ndarray]:
    """Exact leave-one-out predictions of each training run (hyperparameters fixed).

    Returns
    -------
    mean, var
        (n,) each: the predictive mean and variance of run i from the others, output unit.
    """
    gp = emulator.gp
    k_inv = cho_solve((gp.L_, True), np.eye(gp.L_.shape[0]))
    d = np.diag(k_inv)
    y_s = (emulator.y - emulator.y_mean) / emulator.y_std
    mean_s = y_s - (k_inv @ y_s) / d
    return mean_s * emulator.y_std + emulator.y_mean, emulator.y_std**2 / d


@dataclass(frozen=True)
class Diagnostics:
    """How well an emulator predicts runs it did not see.

    Attributes
    ----------
    output
        The output's name.
    kind
        ``loo`` (leave-one-out on the training runs) or ``validation`` (held-out runs).
    standardised_errors
        (y − mean) / sd per run (dimensionless; ~N(0, 1) for a well-calibrated emulator).
    coverage_95, coverage_68
        Fractions of runs inside the central 95 % and 68.27 % predictive intervals (NaN if no runs).
    rmse
        Root-mean-square error of the means, in the output's unit.
    """

    output: str
    kind: str
    standardised_errors: tuple[float, ...]
    coverage_95: float
    coverage_68: float
    rmse: float

    def to_json(self) -> dict:
        """The record as JSON-able values."""
        return {
            "output": self.output,
            "kind": self.kind,
            "standardised_errors": list(self.standardised_errors),
            "coverage_95": self.coverage_95,
            "coverage_68": self.coverage_68,
            "rmse": self.rmse,
        }

    @staticmethod
    def from_json(d: dict) -> Diagnostics:
        """The record from :meth:`to_json`'s values (null → NaN)."""
        nan = float("nan")
        return Diagnostics(
            d["output"],
            d["kind"],
            tuple(nan if e is None else float(e) for e in d["standardised_errors"]),
            nan if d["coverage_95"] is None else float(d["coverage_95"]),
            nan if d["coverage_68"] is None else float(d["coverage_68"]),
            nan if d["rmse"] is None else float(d["rmse"]),
        )


def diagnose(emulator: Emulator, features: np.ndarray | None = None, y: np.ndarray | None = None) -> Diagnostics:
    """Leave-one-out diagnostics (no ``features``), or validation on held-out runs (``features``, ``y``).

    Held-out runs with a NaN output (failed) are left out.
    """
    if features is None:
        kind, y_true = "loo", emulator.y
        mean, var = loo(emulator)
    else:
        kind = "validation"
        y_true = np.asarray(y, dtype=float)
        ok = np.isfinite(y_true)
        y_true = y_true[ok]
        mean, var = predict(emulator, np.atleast_2d(features)[ok]) if ok.any() else (np.empty(0), np.empty(0))
    e = (y_true - mean) / np.sqrt(var)
    nan = float("nan")
    return Diagnostics(
        output=emulator.output,
        kind=kind,
        standardised_errors=tuple(float(v) for v in e),
        coverage_95=float(np.mean(np.abs(e) <= norm.ppf(0.975))) if len(e) else nan,
        coverage_68=float(np.mean(np.abs(e) <= 1.0)) if len(e) else nan,
        rmse=float(np.sqrt(np.mean((y_true - mean) ** 2))) if len(e) else nan,
    )
