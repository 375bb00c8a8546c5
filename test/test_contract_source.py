"""
The graph contract has one source: ``freejoint_common/contract.py``.

Read from the source text (no ROS needed): no QoS profile is constructed, no stamp is
split or joined by hand and no lockstep label is spelt outside the contract module, in the
packages, ``tools/`` and ``bench/``; every topic and service the contract names is in
docs/GRAPH.md's tables, which name the contract module as their source.
"""
import ast
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONTRACT = os.path.join(ROOT, 'src', 'freejoint_common', 'freejoint_common', 'contract.py')
GRAPH_MD = os.path.join(ROOT, 'docs', 'GRAPH.md')
SCANNED = ('src', 'tools', 'bench')
SKIPPED_DIRS = {'test', 'build', 'install', 'log', '__pycache__', '.venv'}

FORBIDDEN = (
    ('a QoS profile constructed (use freejoint_common.contract)', re.compile(r'\bQoSProfile\(')),
    ('nanoseconds per second spelt out (use contract.to_ns / stamp_from_ns / NS_PER_S)',
     re.compile(r'\b1_?000_?000_?000\b|\b10\s*\*\*\s*9\b')),
    ('a stamp joined by hand (use contract.to_ns)', re.compile(r'\.sec\s*\*')),
    ('the lockstep label spelt out (use contract.stamp_label / label_stamp)',
     re.compile(r"""['"]stamp_ns=""")),
)


def sources(root, tops=SCANNED):
    """Yield the path of every Python file under ``root/<top>`` but package tests and builds."""
    for top in tops:
        for folder, dirs, files in os.walk(os.path.join(root, top)):
            dirs[:] = sorted(d for d in dirs if d not in SKIPPED_DIRS)
            for name in sorted(files):
                if name.endswith('.py'):
                    yield os.path.join(folder, name)


def code_lines(path):
    """Yield ``(line number, text)`` of the code of ``path`` (docstrings, comments out)."""
    with open(path, encoding='utf-8') as fh:
        text = fh.read()
    lines = text.splitlines()
    doc = set()
    for node in ast.walk(ast.parse(text, filename=path)):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) \
                and isinstance(node.value.value, str):
            doc.update(range(node.lineno, node.end_lineno + 1))
    for number, line in enumerate(lines, 1):
        if number in doc:
            continue
        if '#' in line and "'" not in line and '"' not in line:
            line = line.split('#', 1)[0]     # a comment (no string on the line)
        yield number, line


def violations(paths, contract=CONTRACT):
    """Return ``'<path>:<line>: <what>'`` for each forbidden construct outside ``contract``."""
    found = []
    for path in paths:
        if os.path.abspath(path) == os.path.abspath(contract):
            continue
        for number, line in code_lines(path):
            for what, pattern in FORBIDDEN:
                if pattern.search(line):
                    found.append('%s:%d: %s' % (os.path.relpath(path, ROOT), number, what))
    return found


def test_no_qos_profile_stamp_arithmetic_or_label_outside_the_contract():
    paths = list(sources(ROOT))
    assert CONTRACT in paths and len(paths) > 30
    assert violations(paths) == []


@pytest.mark.parametrize('line, what', [
    ('QOS = QoSProfile(depth=1000)', 'QoS profile'),
    ('sec = t_ns // 1_000_000_000', 'nanoseconds per second'),
    ('ns = msg.header.stamp.sec * NS + msg.header.stamp.nanosec', 'stamp joined'),
    ("dim.label = 'stamp_ns=%d' % ns", 'lockstep label'),
    ('sec, nsec = divmod(t, 10**9)', 'nanoseconds per second'),
])
def test_a_copy_of_the_contract_is_found(tmp_path, line, what):
    copy = tmp_path / 'tools' / 'copy.py'
    copy.parent.mkdir()
    copy.write_text('"""A module."""\n\n%s\n' % line)
    found = violations(sources(str(tmp_path), ('tools',)))
    assert len(found) == 1 and what in found[0], found


def test_the_contract_itself_is_not_flagged_and_docstrings_are_not_code(tmp_path):
    doc = tmp_path / 'tools' / 'doc.py'
    doc.parent.mkdir()
    doc.write_text('"""\nstamp = sec * 1_000_000_000 + nanosec, QoSProfile(depth=1).\n"""\n')
    assert violations(sources(str(tmp_path), ('tools',))) == []
    assert violations([CONTRACT]) == []


def _contract_names():
    """Return the topic and service names ``contract.py`` defines (from its source)."""
    with open(CONTRACT, encoding='utf-8') as fh:
        tree = ast.parse(fh.read())
    names = []
    for node in tree.body:
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call) and \
                getattr(node.value.func, 'id', '') in ('Topic', 'Service'):
            names.append(node.value.args[0].value)
    return names


def test_graph_md_names_the_contract_module_and_every_contract_topic_and_service():
    with open(GRAPH_MD, encoding='utf-8') as fh:
        text = fh.read()
    assert 'freejoint_common/contract.py' in text or 'freejoint_common.contract' in text
    names = _contract_names()
    assert {'joint_states', '/clock', 'setpoint', '~/reset', '/diagnostics'} <= set(names)
    missing = [name for name in names if '`%s`' % name not in text]
    assert missing == []
