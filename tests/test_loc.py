"""``experiments/rq1_ports/loc.py``: the cloc-style counts behind the RQ1 table, on hand-counted files."""

import importlib.util
import subprocess
import sys
import textwrap
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "experiments" / "rq1_ports" / "loc.py"
_spec = importlib.util.spec_from_file_location("rq1_loc", SCRIPT)
loc = sys.modules["rq1_loc"] = importlib.util.module_from_spec(_spec)   # dataclasses look it up there
_spec.loader.exec_module(loc)
PAPER_TABLE_1, algorithms, count_python, count_yaml = (loc.PAPER_TABLE_1, loc.algorithms, loc.count_python,
                                                       loc.count_yaml)

# Hand count: the code lines are marked  <- code. Everything else is blank, a comment or a docstring.
PYTHON = textwrap.dedent('''\
    """Module docstring
    on two lines."""

    import math  # a trailing comment does not hide the code        <- code 1

    # a comment line
    def f(x):                                                    # <- code 2
        """Docstring."""
        s = """a multi-line string
    that is an expression"""                                     # <- code 3, 4
        t = "# not a comment"                                    # <- code 5
        return (x +                                              # <- code 6
                math.pi)                                         # <- code 7


    class A:                                                     # <- code 8
        'A single-quoted docstring.'
        y = 1; "a bare string after code on the same line"       # <- code 9
        (                                                        # <- code 10
        )                                                        # <- code 11
    ''')

YAML = textwrap.dedent("""\
    # a comment
    name: x        # code 1
    params:        # code 2
      a: 1         # code 3

      text: |      # code 4
        # inside a block scalar: text, code 5
        line       # code 6 (this is part of the text too)
      b: [1,       # code 7
          2]       # code 8
    # the end
    """)


def test_python_lines_are_counted_like_cloc_with_docstrings_as_comments():
    assert count_python(PYTHON) == 11


def test_yaml_comments_do_not_count_but_block_scalar_lines_do():
    assert count_yaml(YAML) == 8


def test_empty_and_comment_only_files_count_zero():
    assert count_python("") == 0
    assert count_python('"""Only a docstring."""\n# and a comment\n') == 0
    assert count_yaml("# nothing but a comment\n") == 0


def _tiny_project(root):
    (root / "algorithms").mkdir()
    (root / "conf" / "algo").mkdir(parents=True)
    (root / "algorithms" / "__init__.py").write_text("")
    (root / "algorithms" / "demo.py").write_text(
        '"""Demo."""\nfrom .demo_util import half\n\n\nclass DemoDrone:\n    speed = half(4)\n')
    (root / "algorithms" / "demo_util.py").write_text("def half(x):\n    # why: a helper\n    return x / 2\n")
    (root / "algorithms" / "stray.py").write_text("X = 1\n")
    (root / "conf" / "algo" / "demo_base.yaml").write_text(
        "# base\nname: demo\ndrone:\n  _target_: swarmbox.algorithms.demo.DemoDrone\n")
    (root / "conf" / "algo" / "demo_fast.yaml").write_text(
        "defaults:\n  - demo_base\n  - _self_\nparams:\n  speed: 9\n")


def test_algorithms_follow_imports_and_defaults(tmp_path):
    _tiny_project(tmp_path)
    rows = {r.name: r for r in algorithms(tmp_path)}
    demo = rows["demo"]
    assert sorted((p.name, n) for p, n in demo.modules) == [("demo.py", 3), ("demo_util.py", 2)]
    assert sorted(demo.configs) == ["demo_base", "demo_fast"]
    assert demo.module_loc == 3 + 2          # demo.py: import, class, speed; demo_util.py: def, return
    assert demo.yaml_loc == 3 + 5            # base: name, drone, _target_; fast: 5 lines
    assert demo.core_loc == 13
    assert rows["stray"].configs == () and rows["stray"].core_loc == 1


def test_report_lists_the_three_ports_beside_the_paper():
    proc = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    rows = {c: r for r in algorithms() for c in r.configs}
    for name, (legacy_b, legacy_c, cpp_b, cpp_c, cfg) in PAPER_TABLE_1.items():
        line = next(ln for ln in out.splitlines() if ln.startswith(name))
        assert line.split()[-12:-3] == [str(legacy_b), str(cpp_b), "0", str(legacy_c), str(cpp_c),
                                        str(rows[cfg].core_loc), str(legacy_b + legacy_c),
                                        str(cpp_b + cpp_c), str(rows[cfg].core_loc)]
        assert rows[cfg].core_loc < cpp_c    # the Python port is shorter than the paper's C++ port
    assert "Every algorithm under algorithms/" in out
