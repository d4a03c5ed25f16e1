"""The house's rules, held by the code itself: a node that is wiring, one entry for messages, kinds as
types, learner classes known to the builder only, every room with a face. Each rule is a search of the
package's source, so a later change that breaks it fails here, not in a review."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import semiparam_ros

PACKAGE = Path(semiparam_ros.__file__).parent
NODE_LINES = 400
LEARNER_CLASSES = {"ParametricModel", "NonparametricModel", "SemiparametricModel", "JointSemiparametricModel",
                   "ConsistentSemiparametricModel", "TwoStageModel", "LearnerBase"}


def _modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def _isinstance_targets(tree: ast.AST) -> list[tuple[int, set[str]]]:
    """Each ``isinstance(x, T)`` call with the names its type argument mentions."""
    found = []
    for node in ast.walk(tree):
        call = isinstance(node, ast.Call) and getattr(node.func, "id", None) == "isinstance"
        if call and len(node.args) == 2:
            names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
            names |= {n.attr for n in ast.walk(node.args[1]) if isinstance(n, ast.Attribute)}
            found.append((node.lineno, names))
    return found


def test_the_node_is_wiring():
    lines = len((PACKAGE / "ros" / "estimator_node.py").read_text().splitlines())
    assert lines <= NODE_LINES, f"ros/estimator_node.py has {lines} lines: policy belongs to serving/"


def test_messages_are_dispatched_in_one_place_and_learner_classes_only_by_the_builder():
    entry = PACKAGE / "core" / "stream" / "pipeline.py"  # SamplePipeline.add
    builder = PACKAGE / "core" / "estimator" / "build.py"  # traits_of, rigid_body_part
    offences = []
    for path in _modules():
        for line, names in _isinstance_targets(ast.parse(path.read_text())):
            if names & {"JointStateData", "WrenchData"} and path != entry:
                offences.append(f"{path.relative_to(PACKAGE)}:{line}: message dispatch")
            if names & LEARNER_CLASSES and path != builder:
                offences.append(f"{path.relative_to(PACKAGE)}:{line}: learner class")
    assert offences == []


def test_output_and_input_kinds_are_types_not_strings():
    """The literals live in the kind types and the parameter table; everything else names the members."""
    allowed = {PACKAGE / "core" / "kinds.py", PACKAGE / "core" / "config.py"}
    literal = re.compile(r"""["'](wrench|joint_torques|joint_states)["']""")
    offences = [f"{p.relative_to(PACKAGE)}:{i}: {line.strip()}" for p in _modules() if p not in allowed
                for i, line in enumerate(p.read_text().splitlines(), 1) if literal.search(line)]
    offences += [f"{p.relative_to(PACKAGE)}:{i}" for p in _modules() for i, line in
                 enumerate(p.read_text().splitlines(), 1) if re.search(r"\b6 if\b", line)]
    assert offences == []


def test_every_room_has_a_face_and_nothing_is_deprecated():
    for init in sorted(PACKAGE.rglob("__init__.py")):
        tree = ast.parse(init.read_text())
        doc = ast.get_docstring(tree) or ""
        assert len(doc) > 40 and doc != "semiparam_ros.", f"{init.relative_to(PACKAGE)}: say what it holds"
        exported = [n for n in tree.body if isinstance(n, ast.Assign)
                    and any(getattr(t, "id", "") == "__all__" for t in n.targets)]
        assert exported, f"{init.relative_to(PACKAGE)} has no __all__"
        names = ast.literal_eval(exported[0].value)
        for name in names:  # every name it exports exists (a module of the package or a name defined)
            assert (init.parent / f"{name}.py").is_file() or (init.parent / name / "__init__.py").is_file() \
                or name in init.read_text(), f"{init.relative_to(PACKAGE)}: {name}"
    assert [p for p in _modules() if "deprecat" in p.read_text().lower()] == []
