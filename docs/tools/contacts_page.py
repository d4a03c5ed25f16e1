"""Fill the contacts page's template (``docs/templates/contacts.md.in``) with the contact reports' numbers.

The words live in the template; this module computes its ``${name}`` placeholders from the
:class:`~semiparam_ros.eval.bags.contact_detection.ContactReport` JSON files that ``scripts/contacts.sh``
writes (``contacts_<log>.json`` in the figures folder; ``<log>`` is ``icub_seed<k>`` for the iCub seeds and
``panda`` for the joint-torque arm). The contact acceptance criteria are evaluated here
(:func:`acceptance`) and shown as yes/no; the template states no finding in words.

Placeholders: ``command``, ``headline`` (the first iCub log's table), ``headline_log``, ``seeds_table``
(one row per log and gate setting), ``acceptance_table``, ``figure``, ``figure_panda``, ``threshold``,
``strong_force``, ``window_s``, ``warmup_s``, ``tolerance_s``.
"""

from __future__ import annotations

import json
import math
import os
import string
from collections.abc import Mapping
from pathlib import Path

from semiparam_ros.atomic import atomic_write_text
from semiparam_ros.eval.bags.contact_detection import ContactReport
from semiparam_ros.report.tables import contacts_table, fmt

__all__ = ["acceptance", "contacts_values", "load_contact_reports", "render_contacts", "write_contacts"]

#: Contact acceptance: error after the contacts within this ratio of before, gate on.
AFTER_BEFORE_MAX = 1.10
#: Payload adopted within this time of the pickup, gate on [s].
ADOPTION_MAX_S = 10.0
#: Recall of the strong episodes at least this, gate on.
RECALL_MIN = 0.95
#: At most this many false alarms per minute, gate on.
FALSE_ALARMS_MAX = 1.0


def load_contact_reports(figures: str | Path) -> dict[str, ContactReport]:
    """Read every ``contacts_<log>.json`` of a folder, by ``<log>``, in name order.

    Raises:
        ValueError: If there is none, or one is not a contact report.
        OSError: If a file cannot be read.
    """
    paths = sorted(Path(figures).glob("contacts_*.json"))
    if not paths:
        raise ValueError(f"no contacts_*.json report in {figures}; run scripts/contacts.sh")
    return {p.stem.removeprefix("contacts_"): ContactReport.from_json(json.loads(p.read_text()))
            for p in paths}


def acceptance(report: ContactReport) -> dict[str, bool]:
    """Evaluate the contact acceptance on one report (the first output group: force, or joint torque).

    Returns:
        ``{criterion: holds}``: ``after_within_10pct`` (gate on), ``gate_off_worse`` (gate off's ratio
        above gate on's), ``adopted_within_10s`` (gate on; false without a pickup), ``recall_strong_95``
        and ``false_alarms_le_1`` (gate on).
    """
    g = next(iter(report.output.groups))
    on, off = report.runs["on"], report.runs["off"]
    adopt = None if on.adoption_s is None else on.adoption_s[g]
    return {
        "after_within_10pct": on.ratio(g) <= AFTER_BEFORE_MAX,
        "gate_off_worse": off.ratio(g) > on.ratio(g),
        "adopted_within_10s": adopt is not None and adopt <= ADOPTION_MAX_S,
        "recall_strong_95": not math.isnan(on.recall_strong) and on.recall_strong >= RECALL_MIN,
        "false_alarms_le_1": on.false_alarms_per_minute <= FALSE_ALARMS_MAX,
    }


def _yes(ok: bool) -> str:
    return "yes" if ok else "**no**"


def _seeds_table(reports: Mapping[str, ContactReport]) -> str:
    header = ["log", "gate", "episodes (≥ strong)", "recall", "recall strong", "false alarms / min",
              "median delay [s]", "before", "after", "after/before", "adopted [s]", "back within 1.5× [s]"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for log, rep in reports.items():
        g = next(iter(rep.output.groups))
        unit = rep.output.groups[g].unit
        for key, r in rep.runs.items():
            strong = sum(e.peak_force >= rep.strong_force for e in r.episodes)
            adopt = None if r.adoption_s is None else r.adoption_s[g]
            rec = None if r.recovery is None else r.recovery[g].recovery_time_s
            lines.append("| " + " | ".join([
                log, key, f"{len(r.episodes)} ({strong})", f"{r.recall:.2f}", f"{r.recall_strong:.2f}",
                f"{r.false_alarms_per_minute:.2f}", f"{r.median_delay_s:.3f}",
                f"{fmt(r.before[g])} {unit}", f"{fmt(r.after[g])} {unit}", f"{r.ratio(g):.3f}",
                "n/a" if r.adoption_s is None else ("never" if adopt is None else f"{adopt:.1f}"),
                "n/a" if r.recovery is None else ("never" if rec is None else f"{rec:.1f}"),
            ]) + " |")
    return "\n".join(lines) + "\n"


def _acceptance_table(reports: Mapping[str, ContactReport]) -> str:
    names = list(acceptance(next(iter(reports.values()))))
    lines = ["| log | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for log, rep in reports.items():
        ok = acceptance(rep)
        lines.append(f"| {log} | " + " | ".join(_yes(ok[n]) for n in names) + " |")
    return "\n".join(lines) + "\n"


def contacts_values(reports: Mapping[str, ContactReport], *, figures: Mapping[str, str],
                    command: str) -> dict[str, str]:
    """Return the template's placeholder values.

    Args:
        reports: Contact reports by log name (the first is the headline).
        figures: ``{"figure": path, "figure_panda": path}`` relative to the page.
        command: The command that regenerates the page.

    Returns:
        Placeholder name → text.
    """
    head_log, head = next(iter(reports.items()))
    return {
        "command": command,
        "headline_log": head_log,
        "headline": contacts_table(head),
        "seeds_table": _seeds_table(reports),
        "acceptance_table": _acceptance_table(reports),
        "threshold": f"{head.threshold:g}",
        "strong_force": f"{head.strong_force:g}",
        "window_s": f"{head.window_s:g}",
        "warmup_s": f"{float(head.protocol.get('warmup_s', math.nan)):g}",
        "tolerance_s": f"{float(head.protocol.get('tolerance_s', math.nan)):g}",
        **figures,
    }


def render_contacts(template: str, values: Mapping[str, str]) -> str:
    """Substitute the values into the template.

    Raises:
        ValueError: If the template names an unknown placeholder.
    """
    try:
        return string.Template(template).substitute(values)
    except KeyError as err:
        raise ValueError(f"the contacts template names an unknown placeholder {err}") from err


def write_contacts(figures: str | Path, out: str | Path, template: str | Path, *,
                   command: str = "bash scripts/contacts.sh") -> Path:
    """Render the contacts page from the reports in ``figures`` and write it atomically.

    Args:
        figures: Folder of ``contacts_*.json``, ``contacts.png`` and ``contacts_panda.png``.
        out: Destination markdown file.
        template: ``docs/templates/contacts.md.in``.
        command: The command that regenerates the page.

    Returns:
        The written path.

    Raises:
        OSError: If a file cannot be read or written.
        ValueError: As :func:`load_contact_reports` and :func:`render_contacts`.
    """
    reports = load_contact_reports(figures)
    start = Path(out).resolve().parent
    rel = {name: os.path.relpath(Path(figures).resolve() / f"{stem}.png", start).replace(os.sep, "/")
           for name, stem in (("figure", "contacts"), ("figure_panda", "contacts_panda"))}
    values = contacts_values(reports, figures=rel, command=command)
    atomic_write_text(out, render_contacts(Path(template).read_text(), values))
    return Path(out)
