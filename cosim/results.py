"""Writing and plotting co-simulation results (a DataFrame indexed by time)."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import pandas as pd


def save_results(df: pd.DataFrame, out_dir, name: str = "results") -> list[Path]:
    """Write ``df`` as ``<name>.csv`` and, if pyarrow is installed, ``<name>.parquet``.

    Parameters
    ----------
    df : DataFrame
        Results indexed by time [s].
    out_dir : path
        Directory (created if missing).
    name : str
        File stem.

    Returns the paths written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{name}.csv"]
    df.to_csv(paths[0])
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        return paths
    paths.append(out / f"{name}.parquet")
    df.to_parquet(paths[1])
    return paths


def plot_estimates(df: pd.DataFrame, truth: Sequence[str], estimate: Sequence[str],
                   measured: Sequence[str | None] | None = None, path=None, title: str = ""):
    """One panel per state: truth, estimate (and the measurement if given).

    Parameters
    ----------
    df : DataFrame
        Results indexed by time [s].
    truth, estimate : sequence of str
        Columns of the true and estimated signals, pairwise.
    measured : sequence of str or None, optional
        Measurement column per pair (None where a state is not measured).
    path : path, optional
        Write the figure to this PNG file.
    title : str
        Figure title.

    Returns the matplotlib Figure.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if len(truth) != len(estimate):
        raise ValueError("truth and estimate must list the same number of columns")
    for col in [*truth, *estimate, *[m for m in (measured or []) if m]]:
        if col not in df.columns:
            raise KeyError(f"no column {col!r}; columns: {', '.join(df.columns)}")
    fig, axes = plt.subplots(len(truth), 1, figsize=(8, 2.2 * len(truth)), sharex=True, squeeze=False)
    for i, (tc, ec) in enumerate(zip(truth, estimate)):
        ax = axes[i, 0]
        if measured and measured[i]:
            ax.plot(df.index, df[measured[i]], ".", ms=2, color="0.7", label="measured")
        ax.plot(df.index, df[tc], "k-", lw=1.2, label="truth")
        ax.plot(df.index, df[ec], "r--", lw=1.0, label="estimate")
        ax.set_ylabel(tc.split(".")[-1])
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    plt.close(fig)
    return fig
