"""The code's shape (``benchmarks/code_shape.py``): no long positional parameter lists and
no ``# fmt: skip`` markers in the lane engines that take records of arrays."""

from tests.benchmark_scripts import load_benchmark, run_benchmark

code_shape = load_benchmark("code_shape")

#: The modules whose kernels take records (``core.compiled.schema``).
RECORD_MODULES = (
    "machining_envs/turning/lanes.py",
    "machining_envs/turning/plant.py",
    "machining_envs/milling/lanes.py",
    "machining_envs/milling/plant.py",
    "machining_envs/core/compiled",
    "machining_envs/core/lanes.py",
)


def test_the_record_modules_have_no_long_parameter_list():
    assert code_shape.long_functions(RECORD_MODULES) == []


def test_the_record_modules_keep_their_layout_to_the_formatter():
    assert code_shape.fmt_skips(RECORD_MODULES) == {}


def test_the_counts_see_what_they_count(tmp_path):
    f = tmp_path / "m.py"
    params = ", ".join(f"a{i}" for i in range(15))
    f.write_text(
        f"def long({params}):\n    return 1  # fmt: skip\n"
        "def short(a, /, b, *c, d=1):\n    s = '# fmt: skip'\n"
    )
    assert code_shape.long_functions([f], root=tmp_path) == [(15, "m.py", "long")]
    assert code_shape.long_functions([f], 2, root=tmp_path)[-1] == (2, "m.py", "short")
    assert code_shape.fmt_skips([f], root=tmp_path) == {"m.py": 1}


def test_the_script_prints_both_counts():
    out = run_benchmark("code_shape.py machining_envs/turning")
    assert "functions with 15+ positional parameters: 0" in out
    assert "# fmt: skip markers:" in out
