"""Reports a user runs on their bags: the paper's protocol, real logs, tables, figures and pages."""

__all__ = [
    "evaluation",
    "figures",
    "per_sample",
    "real_robot",
    "tables",
]
