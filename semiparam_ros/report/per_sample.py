"""Every test sample of a protocol run, for a notebook or Foxglove: a CSV table and a per-output figure.

Columns of the table (one row per test sample, in time order): ``split``, ``stamp_ns`` (exact integers),
``time_s`` (from the first test sample), ``measured.<c>`` for each output component c (a joint name, or
``fx … tz``), then for each model ``<model>.<c>`` (its a-priori prediction) and ``<model>.std.<c>``.

The std is the running noise scale of that model's own a-priori errors
(:class:`~semiparam_ros.core.learners.uncertainty.NoiseScale` with ``uncertainty.noise_time_constant``,
updated after each sample as the node does), without the posterior variance term ``z A⁻¹ zᵀ`` that the
protocol's learners do not return: what the node publishes as σ once the model has seen the region.
Units: N·m for joint torques; N and N·m for a wrench.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from semiparam_ros.atomic import atomic_open, atomic_savefig
from semiparam_ros.core.learners.uncertainty import NoiseScale
from semiparam_ros.eval.protocol.prequential import ProtocolResult

__all__ = ["per_sample_figure", "per_sample_table", "write_per_sample"]


def per_sample_table(result: ProtocolResult, noise_time_constant_s: float
                     ) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Return the column names, the integer columns (``split``, ``stamp_ns``) and the float columns.

    Args:
        result: A protocol run (with its test stamps).
        noise_time_constant_s: τ_s of the std's running noise estimate [s].

    Returns:
        ``(columns, integers (n, 2) int64, values (n, k) float64)``, ``columns`` naming both in order.

    Raises:
        ValueError: A result without stamps (written by an older version).
    """
    if result.stamps_ns is None:
        raise ValueError("this protocol result has no test stamps")
    comps = list(result.output.components)
    splits, size, t = result.targets.shape
    stamps = result.stamps_ns.reshape(-1).astype(np.int64)
    integers = np.stack([np.repeat(np.arange(splits, dtype=np.int64), size), stamps], axis=1)
    measured = result.targets.reshape(-1, t)
    columns = ["split", "stamp_ns", "time_s", *[f"measured.{c}" for c in comps]]
    blocks = [((stamps - stamps[0]) * 1e-9)[:, None], measured]
    for kind in result.kinds:
        pred = result.predictions[kind].reshape(-1, t)
        noise = NoiseScale(t, noise_time_constant_s)
        std = np.empty_like(pred)
        for i in range(pred.shape[0]):
            std[i] = noise.std(0.0)
            noise.update(int(stamps[i]), measured[i] - pred[i], 0.0)
        columns += [f"{kind}.{c}" for c in comps] + [f"{kind}.std.{c}" for c in comps]
        blocks += [pred, std]
    return columns, integers, np.concatenate(blocks, axis=1)


def write_per_sample(result: ProtocolResult, path: str | Path, noise_time_constant_s: float) -> Path:
    """Write :func:`per_sample_table` as CSV (atomically).

    Args:
        result: A protocol run.
        path: Destination ``.csv`` (Parquet needs pyarrow, which is not a dependency: the suffix must be
            ``.csv``).
        noise_time_constant_s: τ_s of the std [s].

    Returns:
        The path written.

    Raises:
        ValueError: Another suffix than ``.csv``, or a result without stamps.
        OSError: The file cannot be written.
    """
    path = Path(path)
    if path.suffix.lower() != ".csv":
        raise ValueError(f"--per-sample writes CSV: give a .csv file, not {path.name!r} (Parquet would need "
                         "pyarrow; pandas.read_csv and Foxglove's CSV import read the CSV)")
    columns, integers, values = per_sample_table(result, noise_time_constant_s)
    with atomic_open(path, "w") as fh:
        writer = csv.writer(fh)
        writer.writerow(columns)
        for ints, row in zip(integers, values, strict=True):
            writer.writerow([str(int(ints[0])), str(int(ints[1])), *(repr(float(v)) for v in row)])
    return path


def per_sample_figure(result: ProtocolResult, path: str | Path, *, title: str = "") -> None:
    """One panel per output component: measured and each model's prediction over the test time.

    Args:
        result: A protocol run (with its test stamps).
        path: Destination PNG.
        title: Figure title.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    comps = list(result.output.components)
    t = len(comps)
    assert result.stamps_ns is not None  # checked by the caller's table
    stamps = result.stamps_ns.reshape(-1)
    time_s = (stamps - stamps[0]) * 1e-9
    fig, axes = plt.subplots(t, 1, figsize=(10, 1.6 * t + 1), sharex=True, squeeze=False)
    measured = result.targets.reshape(-1, t)
    unit = result.output.kind.unit
    for k, comp in enumerate(comps):
        ax = axes[k, 0]
        ax.plot(time_s, measured[:, k], color="0.3", lw=0.8, label="measured")
        for kind in result.kinds:
            ax.plot(time_s, result.predictions[kind].reshape(-1, t)[:, k], lw=0.7, label=kind)
        ax.set_ylabel(f"{comp}\n[{unit}]", fontsize=8)
    axes[0, 0].legend(fontsize=7, ncol=len(result.kinds) + 1, loc="upper right")
    axes[-1, 0].set_xlabel("time from the first test sample [s]")
    if title:
        axes[0, 0].set_title(title)
    fig.tight_layout()
    try:
        atomic_savefig(fig, path, dpi=100)
    finally:
        plt.close(fig)
