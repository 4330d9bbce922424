"""`dynsplines blender-addon --out FILE.zip`: an extension zip as Blender 4.2+ installs it (its manifest
at the top, read with the standard TOML reader, and the package's modules beside it); the add-on's code
imports only Blender's modules and the standard library (it runs in Blender's Python); a bad --out is one
line. Installing and running it in Blender: tests/clients/test_blender_addon.py."""
import ast
import sys
import zipfile

import pytest

from runner.cli import main
from runner.exit_codes import EXIT_INPUT

#: what Blender's own Python has besides the standard library
BLENDER_MODULES = {"bpy", "bpy_extras", "mathutils"}


@pytest.fixture(scope="module")
def addon_zip(tmp_path_factory):
    out = tmp_path_factory.mktemp("addon") / "dynsplines.zip"
    assert main(["blender-addon", "--out", str(out)]) == 0
    return out


def test_the_zip_is_an_extension(addon_zip):
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    with zipfile.ZipFile(addon_zip) as z:
        names = set(z.namelist())
        manifest = tomllib.loads(z.read("blender_manifest.toml").decode())
        init = ast.parse(z.read("__init__.py").decode())
    assert {"blender_manifest.toml", "__init__.py"} <= names and all("/" not in n for n in names), names
    assert manifest["id"] == "dynsplines" and manifest["type"] == "add-on" and manifest["schema_version"] == "1.0.0"
    assert tuple(int(v) for v in manifest["blender_version_min"].split(".")) >= (4, 2, 0)
    functions = {f.name for f in init.body if isinstance(f, ast.FunctionDef)}
    assert {"register", "unregister"} <= functions


def test_the_addon_imports_no_project_code(addon_zip):
    stdlib = set(sys.stdlib_module_names)
    with zipfile.ZipFile(addon_zip) as z:
        for name in (n for n in z.namelist() if n.endswith(".py")):
            for node in ast.walk(ast.parse(z.read(name).decode())):
                if isinstance(node, ast.Import):
                    tops = [a.name.split(".")[0] for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0:
                    tops = [node.module.split(".")[0]]
                else:
                    continue
                assert set(tops) <= stdlib | BLENDER_MODULES, (name, tops)


def test_a_bad_out_is_one_line(tmp_path, capsys):
    assert main(["blender-addon", "--out", str(tmp_path / "addon.txt")]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the add-on is a .zip file" in err, err
    assert main(["blender-addon", "--out", str(tmp_path / "no" / "addon.zip")]) == EXIT_INPUT
    assert "does not exist" in capsys.readouterr().err


def test_the_job_keeps_what_the_commands_warn_of(addon_zip, tmp_path):
    """The job (stdlib only, so it runs here) runs two real commands and keeps their warning lines, each once, in
    the command's own form: what the operators report as warnings beside a result that still comes back."""
    import importlib.util

    with zipfile.ZipFile(addon_zip) as z:
        (tmp_path / "job.py").write_bytes(z.read("job.py"))
    spec = importlib.util.spec_from_file_location("addon_job", tmp_path / "job.py")
    job = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(job)
    say = "import sys; print('solving'); print('  warning: cannot tell the length unit'); sys.stdout.write({!r})"
    run = job.Job([("one", [sys.executable, "-c", say.format("dynsplines: warning: the optimization failed\r\n")]),
                   ("two", [sys.executable, "-c", say.format("a line that mentions no warning\n")])], tmp_path)
    run.run()
    assert run.codes == [0, 0] and run.error is None
    assert run.warnings == ["dynsplines: warning: cannot tell the length unit",
                            "dynsplines: warning: the optimization failed"], run.warnings
