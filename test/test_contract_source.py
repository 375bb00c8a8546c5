"""
The graph contract has one source: ``freejoint_common/contract.py``.

Read from the source text (no ROS needed): no QoS profile is constructed, no stamp is
split or joined by hand and no lockstep label is spelt outside the contract module, in the
packages, ``tools/`` and ``bench/``; nor in the tests (``test/``, ``src/<pkg>/test/``),
where a literal second of nanoseconds as data is fine; every topic and service the contract
names is in docs/GRAPH.md's tables, which name the contract module as their source.
"""
import ast
import functools
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONTRACT = os.path.join(ROOT, 'src', 'freejoint_common', 'freejoint_common', 'contract.py')
CONTRACT_TEST = os.path.join(ROOT, 'src', 'freejoint_common', 'test', 'test_contract.py')
GRAPH_MD = os.path.join(ROOT, 'docs', 'GRAPH.md')
SCANNED = ('src', 'tools', 'bench')
SKIPPED_DIRS = {'test', 'build', 'install', 'log', '__pycache__', '.venv'}

QOS = ('a QoS profile constructed (use freejoint_common.contract)', re.compile(r'\bQoSProfile\('))
JOINED = ('a stamp joined by hand (use contract.to_ns)', re.compile(r'\.sec\s*\*'))
LABEL = ('the lockstep label spelt out (use contract.stamp_label / label_stamp)',
         re.compile(r"""['"]stamp_ns="""))
FORBIDDEN = (
    QOS, JOINED, LABEL,
    ('nanoseconds per second spelt out (use contract.to_ns / stamp_from_ns / NS_PER_S)',
     re.compile(r'\b1_?000_?000_?000\b|\b10\s*\*\*\s*9\b')),
)
FORBIDDEN_IN_TESTS = (
    QOS, JOINED, LABEL,
    ('a stamp split by hand (use contract.stamp_from_ns)',
     re.compile(r'(//|%|divmod\(.*,)\s*(1_?000_?000_?000|10\s*\*\*\s*9)\b')),
)


def sources(root, tops=SCANNED):
    """Yield the path of every Python file under ``root/<top>`` but package tests and builds."""
    for top in tops:
        for folder, dirs, files in os.walk(os.path.join(root, top)):
            dirs[:] = sorted(d for d in dirs if d not in SKIPPED_DIRS)
            for name in sorted(files):
                if name.endswith('.py'):
                    yield os.path.join(folder, name)


@functools.lru_cache(maxsize=None)
def code_lines(path):
    """
    Return ``(line number, text)`` of the code of ``path`` (docstrings, comments out).

    Read once per test process (several tests read every file), as test_structure's
    ``parse``; a test's scratch files each have a tmp_path of their own.
    """
    with open(path, encoding='utf-8') as fh:
        text = fh.read()
    doc = set()
    for node in ast.walk(ast.parse(text, filename=path)):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) \
                and isinstance(node.value.value, str):
            doc.update(range(node.lineno, node.end_lineno + 1))
    code = []
    for number, line in enumerate(text.splitlines(), 1):
        if number in doc:
            continue
        if '#' in line and "'" not in line and '"' not in line:
            line = line.split('#', 1)[0]     # a comment (no string on the line)
        code.append((number, line))
    return tuple(code)


def violations(paths, contract=CONTRACT, forbidden=FORBIDDEN):
    """
    Return ``'<path>:<line>: <what>'`` for each forbidden construct in ``paths``.

    The contract, its own test (which spells the label it checks) and this file are not read.
    """
    found = []
    own = {os.path.abspath(p) for p in (contract, CONTRACT_TEST, __file__)}
    for path in paths:
        if os.path.abspath(path) in own:
            continue
        for number, line in code_lines(path):
            for what, pattern in forbidden:
                if pattern.search(line):
                    found.append('%s:%d: %s' % (os.path.relpath(path, ROOT), number, what))
    return found


def test_no_qos_profile_stamp_arithmetic_or_label_outside_the_contract():
    paths = list(sources(ROOT))
    assert CONTRACT in paths and len(paths) > 30
    assert violations(paths) == []


def test_the_tests_take_the_contract_too():
    paths = list(sources(ROOT, ('test',)))
    src = os.path.join(ROOT, 'src')
    for pkg in sorted(os.listdir(src)):
        folder = os.path.join(src, pkg, 'test')
        if os.path.isdir(folder):
            paths += [os.path.join(folder, n) for n in sorted(os.listdir(folder))
                      if n.endswith('.py')]
    assert len(paths) > 30
    assert violations(paths, forbidden=FORBIDDEN_IN_TESTS) == []


def test_a_stamp_split_in_a_test_is_found_and_a_second_as_data_is_not(tmp_path):
    (tmp_path / 'test').mkdir()
    (tmp_path / 'test' / 'test_x.py').write_text(
        'T0 = 1_000_000_000 + 5\nsec, nsec = divmod(T0, 1_000_000_000)\n')
    found = violations(sources(str(tmp_path), ('test',)), forbidden=FORBIDDEN_IN_TESTS)
    assert len(found) == 1 and 'test_x.py:2: a stamp split' in found[0], found


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
    assert {'joint_states', '/clock', 'setpoints', '~/reset', '/diagnostics'} <= set(names)
    missing = [name for name in names if '`%s`' % name not in text]
    assert missing == []
