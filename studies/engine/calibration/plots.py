"""Figures of a history match, apart from its numerics (they read a :class:`HistoryMatch`, nothing else).

- ``nroy_pairs.png``: for every pair of inputs, the **minimum implausibility** over the other
  inputs (lower triangle) and the **optical depth**, the share of points not ruled out (upper
  triangle), on a grid of the reference sample; 1-D optical depth on the diagonal (Vernon,
  Goldstein & Bower 2010, "Galaxy formation: a Bayesian uncertainty analysis", figs. 7-8).
- ``nroy_fraction.png``: NROY fraction of the original space per wave (log scale).
- ``loo_errors.png``: leave-one-out standardised errors per output and wave, the ±2 band shaded
  (Bastos & O'Hagan 2009, "Diagnostics for Gaussian process emulators").

PNG bytes are deterministic: the Agg backend and no ``Software`` metadata (PNG carries no date).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from studies.engine.calibration.waves import HistoryMatch, reference_implausibility

__all__ = ["BINS", "write_figures"]

BINS = 20
"""Cells per input in the projections."""
_METADATA = {"Software": None}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _ticks(result: HistoryMatch, j: int) -> tuple[list[float], list[str]]:
    inp = result.space.inputs[j]
    if inp.categorical:
        k = len(inp.choices)
        return [(i + 0.5) / k for i in range(k)], [str(c) for c in inp.choices]
    at = [0.0, 0.5, 1.0]
    return at, [f"{v:.3g}" for v in inp.from_unit(np.array(at))]


def _label(result: HistoryMatch, j: int) -> str:
    inp = result.space.inputs[j]
    unit = f" ({inp.unit})" if inp.unit else ""
    return f"{inp.name}{unit}{', log' if inp.log else ''}"


def _binned(q: np.ndarray, value: np.ndarray, i: int, j: int, reduce: str) -> np.ndarray:
    bi = np.minimum((q[:, i] * BINS).astype(int), BINS - 1)
    bj = np.minimum((q[:, j] * BINS).astype(int), BINS - 1)
    cell = bi * BINS + bj
    out = np.full(BINS * BINS, np.nan)
    if reduce == "min":
        np.fmin.at(out, cell, value)
    else:
        count = np.bincount(cell, minlength=BINS * BINS)
        hits = np.bincount(cell, weights=value, minlength=BINS * BINS)
        out = np.where(count > 0, hits / np.maximum(count, 1), np.nan)
    return out.reshape(BINS, BINS).T  # rows: input j (y), columns: input i (x)


def pairs_figure(result: HistoryMatch):
    """Minimum implausibility (lower) and optical depth (upper) for every pair of inputs."""
    plt = _pyplot()
    q, worst = reference_implausibility(result)
    nroy = (worst <= result.settings.cutoff).astype(float)
    d = result.space.dim
    size = max(2.2 * d, 4.0)
    fig, axes = plt.subplots(d, d, figsize=(size, size), squeeze=False)
    extent = (0.0, 1.0, 0.0, 1.0)
    vmax = max(2 * result.settings.cutoff, 1.0)
    im_i = im_d = None
    depth_max = max([1e-3] + [np.nanmax(_binned(q, nroy, c, r, "mean")) for r in range(d) for c in range(d) if r < c])
    for r in range(d):
        for c in range(d):
            ax = axes[r, c]
            if r == c:
                b = np.minimum((q[:, c] * BINS).astype(int), BINS - 1)
                depth = np.bincount(b, weights=nroy, minlength=BINS) / np.maximum(np.bincount(b, minlength=BINS), 1)
                ax.bar((np.arange(BINS) + 0.5) / BINS, depth, width=1 / BINS, color="tab:green")
                ax.set_ylim(0, max(depth.max() * 1.1, 1e-3))
            elif r > c:
                im_i = ax.imshow(
                    np.minimum(_binned(q, worst, c, r, "min"), vmax),
                    origin="lower", extent=extent, aspect="auto", cmap="viridis_r", vmin=0, vmax=vmax,
                )  # fmt: skip
                ax.contour(
                    np.linspace(0.5 / BINS, 1 - 0.5 / BINS, BINS),
                    np.linspace(0.5 / BINS, 1 - 0.5 / BINS, BINS),
                    np.nan_to_num(_binned(q, worst, c, r, "min"), nan=vmax),
                    levels=[result.settings.cutoff], colors="w", linewidths=0.8,
                )  # fmt: skip
            else:
                im_d = ax.imshow(
                    _binned(q, nroy, c, r, "mean"), origin="lower", extent=extent, aspect="auto", cmap="magma",
                    vmin=0, vmax=depth_max,
                )  # fmt: skip
            ticks, labels = _ticks(result, c)
            ax.set_xticks(ticks, labels if r == d - 1 else [], fontsize=6)
            if r != c:
                ticks, labels = _ticks(result, r)
                ax.set_yticks(ticks, labels if c == 0 else [], fontsize=6)
            else:
                ax.tick_params(axis="y", labelsize=6)
            if r == d - 1:
                ax.set_xlabel(_label(result, c), fontsize=7)
            if c == 0 and r != c:
                ax.set_ylabel(_label(result, r), fontsize=7)
    fig.subplots_adjust(left=0.2, right=0.8, bottom=0.1, top=0.88, wspace=0.25, hspace=0.25)
    if im_i is not None:
        fig.colorbar(im_i, cax=fig.add_axes((0.06, 0.25, 0.025, 0.5)), label="minimum implausibility")
    if im_d is not None:
        fig.colorbar(im_d, cax=fig.add_axes((0.88, 0.25, 0.025, 0.5)), label="optical depth (NROY share)")
    fig.suptitle(
        f"NROY after {len(result.waves)} waves: {result.nroy_fraction:.3g} of the space\n"
        f"lower: minimum implausibility (white line: cut-off {result.settings.cutoff:g}); "
        "upper, diagonal: optical depth",
        fontsize=8,
    )
    return fig


def fraction_figure(result: HistoryMatch):
    """NROY fraction of the original space per wave."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(4.5, 3.2))
    k = [0] + [w.index for w in result.waves]
    frac = [1.0] + [w.nroy_fraction for w in result.waves]
    floor = 0.5 / result.settings.n_reference
    ax.semilogy(k, np.maximum(frac, floor), "o-")
    ax.set_xticks(k)
    ax.set_xlabel("wave")
    ax.set_ylabel("NROY fraction of the original space")
    ax.set_title(f"stopped: {result.stopped}", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return fig


def loo_figure(result: HistoryMatch):
    """Leave-one-out standardised errors per output and wave."""
    plt = _pyplot()
    m = len(result.observations)
    fig, axes = plt.subplots(1, m, figsize=(max(3.0 * m, 4.0), 3.0), squeeze=False)
    for j, (ax, o) in enumerate(zip(axes[0], result.observations, strict=True)):
        ax.axhspan(-2, 2, color="0.9")
        for w in result.waves:
            e = np.asarray(w.loo[j].standardised_errors)
            ax.plot(np.full(len(e), w.index) + np.linspace(-0.25, 0.25, len(e)), e, ".", ms=3)
        ax.set_xticks([w.index for w in result.waves])
        ax.set_xlabel("wave")
        ax.set_title(o.name, fontsize=8)
    axes[0, 0].set_ylabel("LOO standardised error")
    fig.tight_layout()
    return fig


def write_figures(result: HistoryMatch, out: str | Path) -> list[Path]:
    """Write ``nroy_pairs.png``, ``nroy_fraction.png`` and ``loo_errors.png`` into ``out``; their paths."""
    plt = _pyplot()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, make in (("nroy_pairs", pairs_figure), ("nroy_fraction", fraction_figure), ("loo_errors", loo_figure)):
        fig = make(result)
        path = out / f"{name}.png"
        fig.savefig(path, format="png", dpi=100, metadata=_METADATA)
        plt.close(fig)
        paths.append(path)
    return paths
