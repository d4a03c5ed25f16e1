"""The project's documentation tooling: results pages, their claims, replicates and acceptance criteria.

Not installed: run from the repository root (``scripts/reproduce.sh``, ``scripts/contacts.sh``,
``scripts/replicates.sh``), over the JSON reports the installed ``evaluate`` writes.
"""
