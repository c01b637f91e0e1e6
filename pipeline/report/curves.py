"""The training figures of the report: ``metrics.jsonl`` (one JSON object a logged step) and its curves, and
the photos' learned appearance."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np


def read_metrics(path: Path) -> tuple[list[dict[str, Any]], int]:
    """The rows of a ``metrics.jsonl`` and the number of lines that did not parse."""
    rows, bad = [], 0
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except ValueError:
            bad += 1
            continue
        if isinstance(row, dict) and isinstance(row.get("step"), int | float):
            rows.append(row)
        else:
            bad += 1
    return rows, bad


_NOT_TERMS = {"step", "seconds", "phase", "loss", "psnr_object", "beta", "lr"}


def training_curves(rows: list[dict[str, Any]]):
    """A matplotlib figure: total loss, object PSNR, each loss term, beta and learning rate against the step;
    the end of the mask-only warm-up marked."""
    from matplotlib.figure import Figure

    steps = np.array([r["step"] for r in rows], np.float64)

    def series(key: str) -> np.ndarray:
        return np.array([r.get(key) if isinstance(r.get(key), int | float) else np.nan for r in rows], np.float64)

    fig = Figure(figsize=(11, 6.5))
    axes = fig.subplots(2, 2)
    fig.subplots_adjust(left=0.07, right=0.93, bottom=0.08, top=0.95, wspace=0.25, hspace=0.35)  # constrained
    # layout takes seconds with log axes
    joint = next((r["step"] for r in rows if r.get("phase") == "joint"), None)

    def positive(v: np.ndarray) -> np.ndarray:  # log axes
        return np.where(v > 0, v, np.nan)

    window = len(rows) // 50  # a running mean over 2 % of the rows on top of the noisy per-batch values

    def smooth(v: np.ndarray) -> np.ndarray:
        ok = np.isfinite(v)
        num = np.convolve(np.where(ok, v, 0), np.ones(window), "same")
        den = np.convolve(ok.astype(float), np.ones(window), "same")
        return np.where(den > 0, num / np.maximum(den, 1), np.nan)

    for ax, key, colour, title in ((axes[0, 0], "loss", "tab:blue", "total loss"),
                                   (axes[0, 1], "psnr_object", "tab:green",
                                    "PSNR on object pixels (dB, training batch)")):
        v = series(key)
        ax.plot(steps, positive(v) if key == "loss" else v, color=colour, lw=0.8, alpha=0.5 if window > 1 else 1)
        if window > 1:
            ax.plot(steps, smooth(v), color="k", lw=1, label=f"running mean of {window}")
            ax.legend(fontsize=7)
        if key == "loss":
            ax.set_yscale("log")
        ax.set_title(title)
    ax = axes[1, 0]
    terms = sorted({k for r in rows for k, v in r.items() if k not in _NOT_TERMS and isinstance(v, int | float)})
    for k in terms:
        ax.plot(steps, positive(series(k)), lw=1, label=k)
    ax.set_yscale("log")
    ax.set_title("loss terms")
    if terms:
        ax.legend(fontsize=7, ncol=2)
    ax = axes[1, 1]
    ax.plot(steps, series("beta"), color="tab:purple", lw=1, label="beta (VolSDF)")
    ax.set_yscale("log")
    ax2 = ax.twinx()
    ax2.plot(steps, series("lr"), color="tab:gray", lw=1, ls="--", label="learning rate")
    ax2.set_yscale("log")
    ax.set_title("beta (solid) and learning rate (dashed)")
    for a in axes.ravel():
        a.set_xlabel("step")
        a.grid(alpha=0.3)
        if joint is not None and len(steps) and joint > steps.min():
            a.axvline(joint, color="k", lw=0.8, ls=":")
    return fig


def appearance_figure(gains: dict[str, list[float]]):
    """A matplotlib figure of each training photo's learned appearance (``{name: [r, g, b]}`` gains relative to
    the photos' geometric mean): its exposure in stops (the gains' geometric mean) and its white balance as
    the red and blue gains over the green."""
    from matplotlib.figure import Figure

    names = list(gains)
    g = np.array([gains[n] for n in names], np.float64)
    x = np.arange(len(names))
    fig = Figure(figsize=(11, 3.2))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.07, right=0.93, bottom=0.3, top=0.9)
    ax.bar(x, np.log2(g).mean(axis=1), color="0.6", label="exposure (stops)")
    ax.set_ylabel("exposure (stops)")
    ax.axhline(0, color="0.3", linewidth=0.6)
    balance = ax.twinx()
    balance.plot(x, g[:, 0] / g[:, 1], "o-", color="tab:red", markersize=3, label="red / green gain")
    balance.plot(x, g[:, 2] / g[:, 1], "o-", color="tab:blue", markersize=3, label="blue / green gain")
    balance.set_ylabel("white balance (gain ratio)")
    ax.set_xticks(x, names, rotation=90, fontsize=6)
    ax.set_xlim(-0.6, len(names) - 0.4)
    fig.legend(loc="upper right", fontsize=7, ncol=3)
    return fig
