"""
The root conftest's ``slow`` lists name tests and modules that exist.

A renamed test or module would otherwise drop out of the list silently and come back into
``make test-fast``; a list entry that names nothing is a stale claim about what test-fast
leaves out.
"""
import ast
import importlib.util
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _root_conftest():
    spec = importlib.util.spec_from_file_location(
        'freejoint_root_conftest', os.path.join(ROOT, 'conftest.py'))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _test_functions(path):
    """Return {name: parametrize source text} of the test functions in the file at ``path``."""
    with open(os.path.join(ROOT, path), encoding='utf-8') as fh:
        text = fh.read()
    found = {}
    for node in ast.parse(text).body:
        if isinstance(node, ast.FunctionDef) and node.name.startswith('test'):
            found[node.name] = ' '.join(ast.get_source_segment(text, d) or ''
                                        for d in node.decorator_list)
    return found


def test_every_slow_module_and_test_exists_and_each_test_says_why():
    conftest = _root_conftest()
    for path, why in conftest.SLOW_MODULES.items():
        assert os.path.isfile(os.path.join(ROOT, path)), path
        assert why, path
    for key, why in conftest.SLOW_TESTS.items():
        path, _, name = key.partition('::')
        name, _, params = name.partition('[')
        functions = _test_functions(path)
        assert name in functions, key
        if params:
            # one case of a parametrized test: each of its values is in a parametrize decorator
            assert 'parametrize' in functions[name], key
            for value in params.rstrip(']').split('-'):
                assert value in functions[name], (key, value)
        assert why, key
