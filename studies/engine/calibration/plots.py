"""Figures of a history match, apart from its numerics (they read a :class:`HistoryMatch`, nothing else).

- ``nroy_pairs.png``: for every pair of the most constraining inputs (:func:`ranked_inputs`, at most
  :data:`PAIRS`), the **minimum implausibility** over the other inputs (lower triangle) and the
  **optical depth**, the share of points not ruled out (upper triangle), on a grid of the reference
  sample; 1-D optical depth on the diagonal (Vernon, Goldstein & Bower 2010, "Galaxy formation: a
  Bayesian uncertainty analysis", figs. 7-8).
- ``nroy_marginals.png``: for every input, its 1-D minimum implausibility and optical depth.
- ``outputs.png``: per observation, what each wave's runs gave beside the observed value and the
  band the cut-off accepts (how near the simulator came, and from which side).
- ``nroy_fraction.png``: NROY fraction of the original space per wave (log scale).
- ``loo_errors.png``: leave-one-out standardised errors per output and wave, the ±2 band shaded
  (Bastos & O'Hagan 2009, "Diagnostics for Gaussian process emulators").

PNG bytes are deterministic: the Agg backend and no ``Software`` metadata (PNG carries no date).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from studies.engine.calibration.waves import HistoryMatch, reference_implausibility

__all__ = ["BINS", "FIGURES", "PAIRS", "profile", "ranked_inputs", "write_figures"]

BINS = 20
"""Cells per input in the projections."""
PAIRS = 6
"""Inputs shown in the pairs figure (the most constraining ones: a 38 × 38 grid is unreadable)."""
COLUMNS = 6
"""Panels per row in the per-input and per-output grids."""
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
        names = [str(c) for c in inp.choices] if k <= 4 else [str(i + 1) for i in range(k)]  # many: their numbers
        return [(i + 0.5) / k for i in range(k)], names
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


def profile(q: np.ndarray, worst: np.ndarray, cutoff: float, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Input ``i``'s 1-D profiles over :data:`BINS` cells: the minimum implausibility and the optical
    depth (share of the cell's reference points not ruled out)."""
    b = np.minimum((q[:, i] * BINS).astype(int), BINS - 1)
    low = np.full(BINS, np.nan)
    np.fmin.at(low, b, worst)
    depth = np.bincount(b, weights=(worst <= cutoff).astype(float), minlength=BINS)
    return low, depth / np.maximum(np.bincount(b, minlength=BINS), 1)


def ranked_inputs(result: HistoryMatch, q: np.ndarray | None = None, worst: np.ndarray | None = None) -> list[int]:
    """Inputs ordered from the most to the least constraining: by how much the 1-D minimum
    implausibility (capped at twice the cut-off) rises from its lowest cell to its highest. An input
    the observations do not constrain has a flat profile, whether NROY is empty or not."""
    if q is None or worst is None:
        q, worst = reference_implausibility(result)
    cap = 2 * result.settings.cutoff
    rise = []
    for i in range(result.space.dim):
        low, _ = profile(q, worst, result.settings.cutoff, i)
        low = np.minimum(np.nan_to_num(low, nan=cap), cap)
        rise.append(float(low.max() - low.min()))
    return sorted(range(result.space.dim), key=lambda i: (-rise[i], i))


def pairs_figure(result: HistoryMatch):
    """Minimum implausibility (lower) and optical depth (upper) for every pair of the :data:`PAIRS`
    most constraining inputs."""
    plt = _pyplot()
    q_all, worst = reference_implausibility(result)
    nroy = (worst <= result.settings.cutoff).astype(float)
    shown = sorted(ranked_inputs(result, q_all, worst)[:PAIRS])
    q = q_all[:, shown]
    d = len(shown)
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
            ticks, labels = _ticks(result, shown[c])
            ax.set_xticks(ticks, labels if r == d - 1 else [], fontsize=6)
            if r != c:
                ticks, labels = _ticks(result, shown[r])
                ax.set_yticks(ticks, labels if c == 0 else [], fontsize=6)
            else:
                ax.tick_params(axis="y", labelsize=6)
            if r == d - 1:
                ax.set_xlabel(_label(result, shown[c]), fontsize=7)
            if c == 0 and r != c:
                ax.set_ylabel(_label(result, shown[r]), fontsize=7)
    fig.subplots_adjust(left=0.2, right=0.8, bottom=0.1, top=0.88, wspace=0.25, hspace=0.25)
    if im_i is not None:
        fig.colorbar(im_i, cax=fig.add_axes((0.06, 0.25, 0.025, 0.5)), label="minimum implausibility")
    if im_d is not None:
        fig.colorbar(im_d, cax=fig.add_axes((0.88, 0.25, 0.025, 0.5)), label="optical depth (NROY share)")
    fig.suptitle(
        f"NROY after {len(result.waves)} waves: {result.nroy_fraction:.3g} of the space "
        f"({d} most constraining of {result.space.dim} inputs)\n"
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
    for wave, f in zip(k, frac, strict=True):
        if f == 0:  # nothing left: drawn at half a reference point, marked so it cannot be read as a value
            ax.semilogy([wave], [floor], "v", color="C3", ms=9)
            ax.annotate(f"0 of {result.settings.n_reference}", (wave, floor), textcoords="offset points",
                        xytext=(-8, 8), ha="right", fontsize=7, color="C3")  # fmt: skip
    ax.set_xticks(k)
    ax.set_xlabel("wave")
    ax.set_ylabel("NROY fraction of the original space")
    ax.set_title(f"stopped: {result.stopped}", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return fig


def _grid(plt, n: int, width: float = 2.3, height: float = 2.0):
    rows = max(1, -(-n // COLUMNS))
    cols = min(n, COLUMNS) if n else 1
    fig, axes = plt.subplots(rows, cols, figsize=(width * cols, height * rows), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    return fig, list(axes.flat[:n])


def loo_figure(result: HistoryMatch):
    """Leave-one-out standardised errors per output and wave."""
    plt = _pyplot()
    fig, axes = _grid(plt, len(result.observations))
    for j, (ax, o) in enumerate(zip(axes, result.observations, strict=True)):
        ax.axhspan(-2, 2, color="0.9")
        for w in result.waves:
            e = np.asarray(w.loo[j].standardised_errors)
            ax.plot(np.full(len(e), w.index) + np.linspace(-0.25, 0.25, len(e)), e, ".", ms=3)
        ax.set_xticks([w.index for w in result.waves])
        ax.set_title(o.name.replace(".", "\n"), fontsize=7)  # frame, then output
        ax.tick_params(labelsize=6)
    fig.supxlabel("wave", fontsize=8)
    fig.supylabel("LOO standardised error (grey: ±2)", fontsize=8)
    fig.tight_layout()
    return fig


def marginals_figure(result: HistoryMatch):
    """Every input's 1-D minimum implausibility (line, left axis) and optical depth (bars, right)."""
    plt = _pyplot()
    q, worst = reference_implausibility(result)
    order = ranked_inputs(result, q, worst)
    fig, axes = _grid(plt, len(order))
    centres = (np.arange(BINS) + 0.5) / BINS
    cap = 2 * result.settings.cutoff
    for ax, i in zip(axes, order, strict=True):
        low, depth = profile(q, worst, result.settings.cutoff, i)
        twin = ax.twinx()
        twin.bar(centres, depth, width=1 / BINS, color="tab:green", alpha=0.35)
        twin.set_ylim(0, 1)
        twin.tick_params(labelsize=6)
        ax.plot(centres, np.minimum(low, cap), color="tab:blue")
        ax.axhline(result.settings.cutoff, color="tab:red", lw=0.8, ls="--")
        ax.set_ylim(0, cap * 1.05)
        ticks, labels = _ticks(result, i)
        ax.set_xticks(ticks, labels, fontsize=6)
        ax.tick_params(axis="y", labelsize=6)
        ax.set_title(_label(result, i), fontsize=7)
    fig.tight_layout()
    return fig


def outputs_figure(result: HistoryMatch):
    """Per observation: each wave's runs (dots), the observed value (black line) and the band the
    cut-off accepts with no emulator error (grey: z ± 3σ, σ² = observation + discrepancy variance;
    for a bound, its accepted side)."""
    plt = _pyplot()
    fig, axes = _grid(plt, len(result.observations))
    c = result.settings.cutoff
    for j, (ax, o) in enumerate(zip(axes, result.observations, strict=True)):
        sd = float(np.sqrt(o.obs_var + o.disc_var))
        lo = -np.inf if o.kind == "at_most" else o.z - c * sd
        hi = np.inf if o.kind == "at_least" else o.z + c * sd
        values = np.concatenate([w.outputs[:, j] for w in result.waves]) if result.waves else np.array([])
        finite = values[np.isfinite(values)]
        span = np.concatenate([finite, [o.z - c * sd, o.z + c * sd]])
        y0, y1 = float(span.min()), float(span.max())
        pad = 0.08 * (y1 - y0 or 1.0)
        ax.axhspan(max(lo, y0 - pad), min(hi, y1 + pad), color="0.88")
        ax.axhline(o.z, color="k", lw=0.8)
        for w in result.waves:
            y = w.outputs[:, j]
            ax.plot(np.full(len(y), w.index) + np.linspace(-0.25, 0.25, len(y)), y, ".", ms=4)
        ax.set_ylim(y0 - pad, y1 + pad)
        ax.set_xticks([w.index for w in result.waves])
        ax.tick_params(labelsize=6)
        unit = f" {o.unit}" if o.unit else ""
        frame_and_output = o.name.replace(".", "\n")
        ax.set_title(f"{frame_and_output}\n{o.kind} {o.z:g}{unit}", fontsize=6)
    fig.supxlabel("wave", fontsize=8)
    fig.tight_layout()
    return fig


FIGURES = {
    "nroy_pairs": pairs_figure,
    "nroy_marginals": marginals_figure,
    "nroy_fraction": fraction_figure,
    "outputs": outputs_figure,
    "loo_errors": loo_figure,
}
"""The figures :func:`write_figures` writes, by file name (without ``.png``)."""


def write_figures(result: HistoryMatch, out: str | Path) -> list[Path]:
    """Write the :data:`FIGURES` into ``out`` as PNG; their paths."""
    plt = _pyplot()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, make in FIGURES.items():
        fig = make(result)
        path = out / f"{name}.png"
        fig.savefig(path, format="png", dpi=100, metadata=_METADATA)
        plt.close(fig)
        paths.append(path)
    return paths
