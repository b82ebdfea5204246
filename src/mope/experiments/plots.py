"""Figures of the paper's Deep-Sea-Treasure experiment (Fig. 2 and Fig. 3), with matplotlib (Agg backend)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

COLORS = {"eql": "tab:gray", "ee": "tab:blue", "pe": "tab:orange", "mope": "tab:green"}


def save_figure(fig: Any, path: str | Path, dpi: int = 120) -> Path:
    """Lay out, write and close a figure; return its path."""
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return Path(path)


def mean_ci(values: np.ndarray, axis: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and a 95% t-interval over ``axis`` (the band collapses to the mean for one seed)."""
    from scipy import stats

    v = np.asarray(values, dtype=np.float64)
    n = v.shape[axis]
    mean = v.mean(axis=axis)
    if n < 2:
        return mean, mean, mean
    half = stats.t.ppf(0.975, n - 1) * v.std(axis=axis, ddof=1) / np.sqrt(n)
    return mean, mean - half, mean + half


def plot_curves(curves: Mapping[str, tuple[np.ndarray, np.ndarray]], path: str | Path, ylabel: str = "coverage ratio",
                title: str = "Deep-Sea-Treasure: CR during training (mean, 95% CI)") -> Path:
    """Fig. 2a: a metric against steps, one line and band per variant.

    Args:
        curves: variant -> (steps ``(T,)``, values ``(seeds, T)``).
        path: Output PNG.
    """
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for name, (steps, values) in curves.items():
        mean, lo, hi = mean_ci(values)
        if np.all((values >= 0) & (values <= 1)):  # shares and ratios: keep the band inside [0, 1]
            lo, hi = np.clip(lo, 0, 1), np.clip(hi, 0, 1)
        c = COLORS.get(name)
        ax.plot(steps, mean, label=f"{name} (n={len(values)})", color=c, lw=2)
        ax.fill_between(steps, lo, hi, color=c, alpha=0.2)
    ax.set_xlabel("environment steps")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend()
    save_figure(fig, path, dpi=120)
    return Path(path)


def plot_fronts(ccs: np.ndarray, found: Mapping[str, np.ndarray], path: str | Path) -> Path:
    """Fig. 2b: the true (discounted) CCS and the distinct solutions each variant recovered."""
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    order = np.argsort(ccs[:, 0])
    ax.plot(ccs[order, 0], ccs[order, 1], "k--", lw=1, alpha=0.6)
    ax.scatter(ccs[:, 0], ccs[:, 1], s=160, facecolors="none", edgecolors="k", lw=1.5, label="true CCS", zorder=3)
    markers = ["o", "s", "^", "D"]
    for (name, pts), mk in zip(found.items(), markers, strict=False):
        ax.scatter(pts[:, 0], pts[:, 1], s=36, marker=mk, color=COLORS.get(name), label=name, alpha=0.85, zorder=4)
    ax.set_xlabel("treasure (discounted)")
    ax.set_ylabel("time (discounted)")
    ax.set_title("Deep-Sea-Treasure: true CCS and recovered solutions (seed 0)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path, dpi=120)
    return Path(path)


def plot_preference_solutions(panels: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]], ccs: np.ndarray,
                              path: str | Path) -> Path:
    """Fig. 3a: weight on treasure against the treasure component of the solution found, beside the optimum.

    Args:
        panels: variant -> (prefs ``(n, 2)``, found discounted returns ``(n, 2)``, optimal returns ``(n, 2)``).
        ccs: The discounted CCS (to mark solutions no preference recovered).
        path: Output PNG.
    """
    from mope.metrics import match_matrix

    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.0), squeeze=False, sharey=True)
    for ax, (name, (prefs, found, best)) in zip(axes[0], panels.items(), strict=True):
        order = np.argsort(prefs[:, 0])
        w, f, b = prefs[order, 0], found[order, 0], best[order, 0]
        ok = np.all(np.isclose(found[order], best[order], atol=1e-2, rtol=1e-3), axis=1)
        ax.plot(w, b, ls=":", color="gray", lw=2, label="optimal solution")
        ax.scatter(w[ok], f[ok], s=6, color="tab:green", label="found, optimal")
        ax.scatter(w[~ok], f[~ok], s=6, color="tab:red", label="found, not optimal")
        missed = ~match_matrix(ccs, found).any(axis=1) if len(found) else np.ones(len(ccs), bool)
        for v in ccs[missed, 0]:
            ax.axhline(v, color="tab:red", ls="--", lw=0.8, alpha=0.6)
        ax.set_title(f"{name}: {int((~ok).sum())} of {len(ok)} preferences not optimal, "
                     f"{int(missed.sum())} CCS points missed", fontsize=9)
        ax.set_xlabel("preference weight on treasure")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("treasure of the solution (discounted)")
    axes[0][0].legend(fontsize=8, loc="upper left")
    save_figure(fig, path, dpi=120)
    return Path(path)


def plot_discriminator_maps(maps: Mapping[str, np.ndarray], sea_map: np.ndarray, path: str | Path) -> Path:
    """Fig. 3b: the discriminator's predicted weight on treasure at every cell of the DST grid.

    Args:
        maps: variant -> ``(rows, cols)`` predicted E[w_treasure | s]; NaN where the cell is rock.
        sea_map: The environment's map (treasures are annotated).
        path: Output PNG.
    """
    fig, axes = plt.subplots(1, len(maps), figsize=(4.6 * len(maps), 4.2), squeeze=False)
    for ax, (name, grid) in zip(axes[0], maps.items(), strict=True):
        im = ax.imshow(grid, cmap="viridis", vmin=0, vmax=1)
        for (r, c), v in np.ndenumerate(sea_map):
            if v > 0:
                ax.text(c, r, f"{v:g}", ha="center", va="center", fontsize=6, color="white")
        ax.set_title(f"{name}: discriminator E[w_treasure | s]", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        fig.colorbar(im, ax=ax, fraction=0.046)
    save_figure(fig, path, dpi=120)
    return Path(path)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)
