"""``export_urdf``: the identified, physically consistent inertials and friction of a checkpoint as a URDF.

::

    export_urdf --checkpoint kuka.npz --out kuka_identified.urdf

Prints what the data determined (the information matrix's condition number and least-excited
directions) and, per link, which quantities came from the data and which from the URDF; writes the
robot's URDF with each link's ``<inertial>`` and each joint's ``<dynamics damping friction>``, the same
lines as a comment at its top. A link the data left implausible (a mass beyond 4× or below ¼ of the
URDF's, a centre of mass far from its frame) keeps its URDF values and is named in a warning, as is a
payload the distal link carries. Argument parsing only (:mod:`semiparam_ros.core.rigid_body.plausible`).
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
        links = model.plausible_links()
        print(model.excitation().text())
        for line in links.comments():
            print(f"  {line}")
        atomic_write_text(args.out, export_urdf(model.estimator.regressor, links.estimate, links.comments()))
    except (ValueError, OSError) as err:
        return error_exit("export_urdf", err)
    warning = links.warning()
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
    print(f"wrote {args.out} (projection solved in {1e3 * links.estimate.solve_s:.0f} ms)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
