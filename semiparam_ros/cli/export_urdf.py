"""``export_urdf``: the identified, physically consistent inertials and friction of a checkpoint as a URDF.

::

    export_urdf --checkpoint kuka.npz --out kuka_identified.urdf

Prints what the data determined (the information matrix's condition number and least-excited
directions) and the consistent link masses; writes the robot's URDF with each identified link's
``<inertial>`` and each joint's ``<dynamics damping friction>``. Argument parsing only
(:mod:`semiparam_ros.core.rigid_body.identification`).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from semiparam_ros.cli.exit_codes import error_exit

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``export_urdf``."""
    p = argparse.ArgumentParser(prog="export_urdf", description="Write the identified, physically consistent "
                                "inertial parameters and friction of a checkpoint into its robot's URDF.")
    p.add_argument("--checkpoint", type=Path, required=True, help="a self-contained checkpoint")
    p.add_argument("--out", type=Path, required=True, help="the URDF to write")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``export_urdf``; returns the exit status (0 done, 2 invalid input, 1 an I/O failure)."""
    args = build_parser().parse_args(argv)
    from semiparam_ros.atomic import atomic_write_text
    from semiparam_ros.core.rigid_body.identification import export_urdf
    from semiparam_ros.serving.learned_model import load_model

    try:
        model = load_model(args.checkpoint)
        estimate = model.consistent()
        print(model.excitation().text())
        for i, body in enumerate(estimate.body_names):
            mass, com, _ = estimate.link(i)
            print(f"  {body}: {mass:.4g} kg, centre of mass {com.round(4).tolist()} m")
        atomic_write_text(args.out, export_urdf(model.estimator.regressor, estimate))
    except (ValueError, OSError) as err:
        return error_exit("export_urdf", err)
    print(f"wrote {args.out} (projection solved in {1e3 * estimate.solve_s:.0f} ms)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
