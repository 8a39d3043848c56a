"""Bring your own predictor: ``module:Class`` import paths, entry points of the group
``posbench.predictors``, ``--set NAME.OPTION=VALUE`` and ``bench predictors``.

The guide's worked example (docs/guides/own-predictor.md) is taken from the page itself (its
``damped.py`` block and its ``pyproject.toml``), so the page cannot drift (its commands run
as the docs' examples too); the runs below go through the ``bench`` CLI in a subprocess, as
the guide's do, with three commands (import path, an alias with ``--set``, an
entry point).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from helpers import ROOT

from posbench.errors import UsageError
from posbench.predictors import registry
from posbench.predictors.base import Predictor
from posbench.predictors.catalogue import ENTRY_POINT, IMPORT_PATH
from posbench.predictors.kalman.kf import JERK_PSDS
from posbench.predictors.registry import (
    PredictorError,
    available,
    base_name,
    constructor_options,
    create,
    is_import_path,
    predictor_class,
    resolve,
    tuned_params,
)
from posbench.replay.predictor_options import merge_options, parse_set, parse_value
from posbench.replay.predictor_setup import validate_predictors, with_model_aliases

GUIDE = ROOT / "docs" / "guides" / "own-predictor.md"
SECTION = GUIDE.read_text(encoding="utf-8")
#: the runs of the example: by import path, an alias of it with an option, an entry point
RUNS = (
    ["run", "-p", "kf,damped:DampedVelocity", "--out", "damped-run"],
    [
        "run",
        "-p",
        "cv,damped:DampedVelocity,damped:DampedVelocity@fast",
        "--set",
        "damped:DampedVelocity@fast.tau_s=0.5",
    ],
    ["run", "-p", "kf,damped", "--set", "damped.tau_s=4"],
)
#: first-screen columns that are the same in every run of a seed: the errors and x limit
#: (the last, the step latency, is not)
ERROR_CELLS = slice(0, -1)


# ----------------------------------------------------------------------- the guide
def readme_blocks(lang: str) -> list[str]:
    """The fenced ``lang`` blocks of the guide "Your own predictor"."""
    return re.findall(rf"```{lang}\n(.*?)```", SECTION, re.S)


def readme_predictor_code() -> str:
    blocks = [b for b in readme_blocks("python") if "class DampedVelocity(Predictor)" in b]
    assert len(blocks) == 1, "the guide lost its damped.py example"
    return blocks[0]


def readme_runs() -> list[tuple[list[str], dict[str, list[str]]]]:
    """Each run of :data:`RUNS` with the error cells it must print (none given: the guide
    shows no tables; the Ray test compares its figures with a local run's)."""
    return [(list(args), {}) for args in RUNS]


def table_rows(text: str) -> dict[str, list[str]]:
    """Rows of the first table printed (the summary): predictor name -> its cells after the
    name (later tables, such as the paired comparison, are not read)."""
    rows = {}
    for line in text.splitlines():
        if line.startswith("└"):
            break
        if line.startswith("│"):
            cells = [c.strip() for c in line.strip().strip("│").split("│")]
            rows[cells[0]] = cells[1:]
    return rows


def readme_distribution() -> tuple[str, str, dict[str, str]]:
    """Name, version and ``posbench.predictors`` entry points of the guide's pyproject.toml."""
    (block,) = readme_blocks("toml")
    meta = tomllib.loads(block)["project"]
    return meta["name"], meta["version"], meta["entry-points"]["posbench.predictors"]


def install_dist_info(site: Path, name: str, version: str, entry_points: dict[str, str]) -> None:
    """A throwaway installed distribution: ``NAME-VERSION.dist-info`` with METADATA and
    entry_points.txt, found by importlib.metadata when ``site`` is on sys.path."""
    d = site / f"{name.replace('-', '_')}-{version}.dist-info"
    d.mkdir(parents=True)
    (d / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
    (d / "entry_points.txt").write_text(
        "[posbench.predictors]\n" + "".join(f"{k} = {v}\n" for k, v in entry_points.items())
    )


@pytest.fixture(scope="module")
def plugin_dir(tmp_path_factory) -> Path:
    """A folder holding the guide's damped.py."""
    d = tmp_path_factory.mktemp("plugin")
    (d / "damped.py").write_text(readme_predictor_code())
    return d


@pytest.fixture(scope="module")
def site_dir(tmp_path_factory, plugin_dir) -> Path:
    """A site folder with the guide's distribution installed (damped.py and its dist-info)
    and a broken one (an entry point whose module does not exist, one shadowing ``kf``)."""
    site = tmp_path_factory.mktemp("site")
    (site / "damped.py").write_text(readme_predictor_code())
    install_dist_info(site, *readme_distribution())
    install_dist_info(
        site,
        "broken-plugin",
        "1.0",
        {"broken": "no_such_plugin_module_x:Nope", "kf": "damped:DampedVelocity"},
    )
    return site


def bench(
    *args: str, cwd: Path, path: list[Path] = (), timeout: float = 300
) -> subprocess.CompletedProcess:
    """``bench ARGS`` in a subprocess, ``path`` in front of PYTHONPATH; tables printed whole."""
    pythonpath = (
        [str(p) for p in path]
        + [str(ROOT)]
        + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(pythonpath), "COLUMNS": "300"}
    return subprocess.run(
        [sys.executable, "-m", "posbench", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=timeout,
        env=env,
    )


def one_error_line(r: subprocess.CompletedProcess) -> str:
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stdout + r.stderr, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    return lines[0]


def run_readme_command(
    args: list[str],
    readme_rows: dict[str, list[str]],
    cwd: Path,
    path: list[Path],
    extra: tuple[str, ...] = (),
) -> dict:
    """Run one example command (its --out moved into ``cwd``); its table must show the error
    figures of ``readme_rows`` (where given); returns its results.json (the printed rows in
    its ``_rows``)."""
    args = list(args)
    cwd.mkdir(parents=True, exist_ok=True)
    if "--out" in args:
        args[args.index("--out") + 1] = str(cwd / "out")
    else:
        args += ["--out", str(cwd / "out")]
    r = bench(*args, *extra, cwd=cwd, path=path)
    assert r.returncode == 0, r.stdout + r.stderr
    rows = table_rows(r.stdout)
    assert set(readme_rows) <= set(rows), (list(rows), r.stdout)
    for name, cells in readme_rows.items():
        assert rows[name][ERROR_CELLS] == cells[ERROR_CELLS], (name, rows[name], cells)
    res = json.loads((cwd / "out" / "results.json").read_text())
    res["_rows"] = rows
    return res


# ------------------------------------------------------------------ end to end
@pytest.mark.slow
def test_readme_example_by_import_path(plugin_dir, tmp_path):
    """(a) ``module:Class`` with the file's folder on PYTHONPATH (run from another folder),
    and the --set example (an alias of an import path)."""
    (args, rows), (args2, rows2), _ = readme_runs()
    assert "damped:DampedVelocity" in args[args.index("-p") + 1]
    res = run_readme_command(args, rows, tmp_path / "a", [plugin_dir])
    assert res["config"]["predictors"] == ["kf", "damped:DampedVelocity"]
    assert (
        res["predictors"]["damped:DampedVelocity"]["future"]["count"]
        == res["predictors"]["kf"]["future"]["count"]
        > 0
    )
    res = run_readme_command(args2, rows2, tmp_path / "b", [plugin_dir])
    assert res["config"]["predictor_options"] == {"damped:DampedVelocity@fast": {"tau_s": 0.5}}
    # the alias with tau_s = 0.5 and the default (2 s) are different predictors
    assert (
        res["predictors"]["damped:DampedVelocity@fast"]["future"]["mean_m"]
        != res["predictors"]["damped:DampedVelocity"]["future"]["mean_m"]
    )


@pytest.mark.slow
def test_import_path_from_the_current_folder(plugin_dir, tmp_path):
    """As the installed ``bench`` script runs (its own folder first on sys.path, not the
    current one): a module in the current folder is found all the same."""
    script = (
        "import sys; sys.path[:] = [p for p in sys.path if p not in ('', '.')]; "
        "sys.argv = ['bench', 'run', '-p', 'damped:DampedVelocity', '--workers', '1', "
        f"'--out', {str(tmp_path / 'o')!r}]; from posbench.cli.app import main; main()"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "300"}
    r = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        cwd=plugin_dir,
        env=env,
        timeout=300,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "damped:DampedVelocity" in table_rows(r.stdout)


@pytest.mark.slow
def test_readme_example_as_entry_point(site_dir, tmp_path):
    """(b) through an installed distribution's entry point: `bench predictors --json` lists it
    (and notes the broken and the shadowing one), `bench run -p kf,damped` prints the
    same figures, and the broken plugin breaks only the runs that name it."""
    name, version, eps = readme_distribution()
    assert eps == {"damped": "damped:DampedVelocity"}
    r = bench("predictors", "--json", cwd=tmp_path, path=[site_dir])
    assert r.returncode == 0, r.stderr
    listing = json.loads(r.stdout)
    by = {p["name"]: p for p in listing["predictors"]}
    assert by["damped"] == {
        "name": "damped",
        "source": "entry point",
        "distribution": f"{name} {version}",
        "target": "damped:DampedVelocity",
        "error": None,
        "description": "Velocity from the last two fixes, decaying with "
        "time constant tau_s [s] after the newest.",
    }
    assert by["kf"]["source"] == "built-in"  # a built-in wins over an entry point
    assert "no_such_plugin_module_x" in by["broken"]["error"]
    assert any("entry point kf of broken-plugin 1.0 is ignored" in n for n in listing["notes"])
    assert any("no_such_plugin_module_x" in n for n in listing["notes"])
    r = bench("predictors", cwd=tmp_path, path=[site_dir])
    assert r.returncode == 0 and "entry point (posbench-damped 0.1.0)" in r.stdout, r.stderr
    assert (
        "note: predictor broken (entry point no_such_plugin_module_x:Nope of broken-plugin "
        "1.0): no module named 'no_such_plugin_module_x'" in " ".join(r.stdout.split())
    )

    _, _, (args, rows) = readme_runs()
    assert args[:3] == ["run", "-p", "kf,damped"]
    res = run_readme_command(args, rows, tmp_path / "ep", [site_dir])
    assert res["config"]["predictor_options"] == {"damped": {"tau_s": 4}}
    r = bench("run", "-p", "kf", "--out", str(tmp_path / "kf"), cwd=tmp_path, path=[site_dir])
    assert r.returncode == 0, r.stderr
    line = one_error_line(
        bench("run", "-p", "kf,broken", "--out", str(tmp_path / "x"), cwd=tmp_path, path=[site_dir])
    )
    assert (
        "predictor broken (entry point no_such_plugin_module_x:Nope of broken-plugin 1.0)" in line
    )
    assert not (tmp_path / "x").exists()


def test_check_accepts_import_paths_and_entry_points(site_dir, tmp_path):
    for spec in ("damped:DampedVelocity", "damped"):
        r = subprocess.run(
            [sys.executable, "-m", "posbench", "check", spec, "--json"],
            capture_output=True,
            text=True,
            cwd=tmp_path,
            timeout=300,
            env={**os.environ, "PYTHONPATH": f"{site_dir}{os.pathsep}{ROOT}"},
        )
        assert r.returncode == 0, r.stdout + r.stderr
        assert json.loads(r.stdout)["passed"] is True


# ------------------------------------------------------------------------- Ray
def _ray():
    if os.environ.get("CI"):
        import ray  # CI installs the dev extra, which has ray: the test must run there

        return ray
    return pytest.importorskip("ray")


@pytest.mark.slow
@pytest.mark.serial  # a local Ray, one at a time (tests/bench/test_executor_ray.py)
def test_readme_example_under_ray(plugin_dir, tmp_path):
    """The guide's import-path example on `--executor ray`: the error figures the guide
    prints, which a local run gives (test_readme_example_by_import_path)."""
    _ray()
    (args, rows), _, _ = readme_runs()
    run_readme_command(args, rows, tmp_path / "ray", [plugin_dir], extra=("--executor", "ray"))


@pytest.mark.slow
@pytest.mark.serial
def test_ray_workers_get_the_plugin_folder(plugin_dir, monkeypatch):
    """A module the driver imports through its sys.path only (not PYTHONPATH, not the
    current folder, both of which Ray passes on by itself) is found by the workers because
    each task gets its folder on PYTHONPATH; without that, every task fails to import it."""
    ray = _ray()
    import posbench.replay.executors as executors
    from posbench.config import RunConfig
    from posbench.replay.executors import run_local, run_ray, worker_runtime_env
    from posbench.scenarios.synthetic import default_drives

    monkeypatch.syspath_prepend(str(plugin_dir))
    assert str(plugin_dir) not in os.environ.get("PYTHONPATH", "")
    cfg = RunConfig(predictors=("cv", "damped:DampedVelocity"))
    predictor_class("damped:DampedVelocity")
    assert worker_runtime_env(cfg.predictors) == {
        "env_vars": {"PYTHONPATH": f"{os.path.realpath(plugin_dir)}{os.pathsep}${{PYTHONPATH}}"}
    }
    assert worker_runtime_env(("cv", "kf")) is None
    drives = default_drives(seed=0)[:1]
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        remote = run_ray(drives, cfg)
        monkeypatch.setattr(executors, "worker_runtime_env", lambda names: None)
        without = run_ray(drives, cfg, max_retries=0)
    finally:
        ray.shutdown()
    assert not remote[0].skipped
    local = run_local(drives, cfg, workers=1)
    assert remote[0].traces.equals(local[0].traces)
    assert without[0].skipped and "no module named 'damped'" in without[0].skipped


# -------------------------------------------------------------------- registry
def test_resolve_every_form_without_importing():
    assert resolve("kf").source == "built-in"
    e = resolve("mypkg.mod:Outer.Inner@fast")
    assert (e.source, e.target) == (IMPORT_PATH, "mypkg.mod:Outer.Inner")
    assert is_import_path("a.b:C@x") and not is_import_path("kf@slow")
    assert base_name("a.b:C@x") == "a.b:C"
    for bad, needle in [
        ("module:", "expected a registered name or module:Class"),
        (":Class", "expected a registered name or module:Class"),
        ("a-b:C", "expected a registered name or module:Class"),
        ("kf@", "alias after @ is empty"),
        ("nope", "unknown predictor 'nope'; known: cv, ekf, hybrid, kf"),
    ]:
        with pytest.raises(PredictorError, match=re.escape(needle)):
            resolve(bad)


@pytest.mark.parametrize(
    ("spec", "needle"),
    [
        ("nosuchmodule:X", "nosuchmodule:X: no module named 'nosuchmodule' (put the folder"),
        ("os:path", "os:path: path is not a class (it is a module)"),
        (
            "collections:OrderedDict",
            "OrderedDict is not a subclass of posbench.predictors.base.Predictor",
        ),
        ("collections:Nope", "module collections has no 'Nope'"),
    ],
)
def test_import_path_errors(spec, needle):
    with pytest.raises(PredictorError) as e:
        predictor_class(spec)
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_entry_points_are_lazy(tmp_path, monkeypatch):
    """Listing names reads metadata only; the plugin is imported when its class is needed,
    and a broken one fails only then."""
    (tmp_path / "lazy_plugin_x.py").write_text(
        "import pathlib\npathlib.Path(__file__).with_name('imported').write_text('yes')\n"
        "from posbench.predictors.cv import ConstantVelocity\n\n\n"
        "class Lazy(ConstantVelocity):\n    '''A lazy one.\n\n    More text.'''\n"
    )
    install_dist_info(
        tmp_path,
        "lazy-x",
        "2.0",
        {"lazy": "lazy_plugin_x:Lazy", "gone": "gone_module_x:G", "bad@name": "lazy_plugin_x:Lazy"},
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    names = available()
    assert names["lazy"].source == ENTRY_POINT and names["lazy"].distribution == "lazy-x 2.0"
    assert "gone" in names and "bad@name" not in names
    assert any("'bad@name' of lazy-x 2.0 is ignored" in n for n in registry.entry_point_notes())
    assert not (tmp_path / "imported").exists() and "lazy_plugin_x" not in sys.modules
    assert type(create("kf")).__name__ == "KalmanBank"  # a broken plugin breaks nothing else
    validate_predictors(["kf"], {})
    assert registry.description("lazy") == "A lazy one."
    assert (tmp_path / "imported").exists()
    p = create("lazy@two", None, window_s=0.5)
    assert isinstance(p, Predictor) and p.window_s == 0.5
    with pytest.raises(
        UsageError,
        match=r"predictor gone \(entry point gone_module_x:G of "
        r"lazy-x 2.0\): no module named 'gone_module_x'",
    ):
        validate_predictors(["kf", "gone"], {})
    sys.modules.pop("lazy_plugin_x", None)


class TakesAnything(Predictor):
    """A predictor whose constructor takes any keyword."""

    def __init__(self, **options) -> None:
        self.options = options

    def reset(self) -> None:
        pass

    def observe_gps(self, t: float, x: float, y: float) -> None:
        pass

    def position_at(self, t: float) -> tuple[float, float]:
        return (0.0, 0.0)


def test_constructor_options():
    opts, any_kw = constructor_options(predictor_class("cv"))
    assert (
        opts == {"window_s": 0.0, "fix_sigma": 0.06, "accel_sigma": 1.0, "cov_scale": 1.0}
        and not any_kw
    )
    assert constructor_options(TakesAnything) == ({}, True)
    validate_predictors(
        [f"{__name__}:TakesAnything"], {f"{__name__}:TakesAnything": {"whatever": [1, 2]}}
    )


# ------------------------------------------------------------------------ --set
@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("4", 4),
        ("0.5", 0.5),
        ("true", True),
        ("null", None),
        ('"4"', "4"),
        ("[1, 2]", [1, 2]),
        ("lbfgs", "lbfgs"),
        ("no", "no"),
        ("path/to/m.onnx", "path/to/m.onnx"),
    ],
)
def test_set_values_are_json_else_text(text, value):
    assert parse_value(text) == value


@pytest.mark.parametrize("text", ["[1,", '{"gate": 0', '"open'])
def test_set_values_that_start_as_json_must_parse(text):
    with pytest.raises(ValueError, match="is not valid JSON"):
        parse_value(text)


def test_set_splits_at_the_last_dot():
    opts, given = parse_set(
        [
            "kf.jerk_psd=4.0",
            "kf@v1.2.gps_sigma=0.1",
            "mypkg.mod:Damped@fast.tau_s=0.5",
            "lstm.fit=lbfgs",
        ]
    )
    assert opts == {
        "kf": {"jerk_psd": 4.0},
        "kf@v1.2": {"gps_sigma": 0.1},
        "mypkg.mod:Damped@fast": {"tau_s": 0.5},
        "lstm": {"fit": "lbfgs"},
    }
    assert given["kf@v1.2", "gps_sigma"] == "--set kf@v1.2.gps_sigma=0.1"


@pytest.mark.parametrize(
    ("values", "needle"),
    [
        (["kf=1"], "--set kf=1: names no option"),
        (["kf.jerk_psd"], "expected NAME.OPTION=VALUE"),
        ([".x=1"], "names no predictor"),
        (["kf.=1"], "is not an option name"),
        (["kf.jerk-psd=1"], "'jerk-psd' is not an option name"),
        (["kf.jerk_psd="], "no value"),
        (["kf.jerk_psd=1", "kf.jerk_psd=1"], "set twice"),
    ],
)
def test_set_syntax_errors(values, needle):
    with pytest.raises(UsageError, match=re.escape(needle)):
        parse_set(values)


def test_set_and_model_must_agree(tmp_path):
    folder = tmp_path / "m"
    folder.mkdir()
    (folder / "model.onnx").write_bytes(b"")
    sets, given = parse_set([f"lstm.model={folder}", "lstm.fit=lbfgs"])
    merged, given = merge_options({"lstm": {"model": str(folder / "model.onnx")}}, sets, given)
    assert merged == {"lstm": {"model": str(folder), "fit": "lbfgs"}}
    assert given["lstm", "model"].startswith("--model lstm=")
    sets, given = parse_set([f"lstm.model={tmp_path / 'other.onnx'}"])
    with pytest.raises(UsageError, match="disagree"):
        merge_options({"lstm": {"model": str(folder)}}, sets, given)


def test_set_alias_joins_the_run_and_tuned_values_come_first():
    opts, given = parse_set(["kf@slow.jerk_psd=1", "kf.jerk_psd=4.0"])
    names = with_model_aliases(("kf",), opts)
    assert names == ("kf", "kf@slow")
    assert validate_predictors(names, opts, given) == opts
    tuned = create("kf", "rtk")
    assert tuned.cov_scale == tuned_params("kf", "rtk")["cov_scale"] != 1.0  # tuned.json
    assert tuned.jerk_psds == JERK_PSDS
    assert create("kf", "rtk", **opts["kf"]).jerk_psds == (4.0,)


def test_set_errors_name_the_predictor_and_option():
    opts, given = parse_set(["kf.gps_sigma=0.1", "kf.jerk_psd=x"])
    with pytest.raises(UsageError) as e:
        validate_predictors(["kf"], opts, given)
    assert str(e.value).startswith(
        "--set kf.jerk_psd=x: kf.jerk_psd takes a number or null, not 'x'; see `bench predictors"
    )
    opts, given = parse_set(["kf.gps_sigma=0.1", "kf.jerk_psd=1e9"])
    with pytest.raises(UsageError) as e:
        validate_predictors(["kf"], opts, given)
    assert str(e.value).startswith(
        "--set kf.jerk_psd=1e9: predictor kf rejects jerk_psd=1000000000.0: kf: jerk_psd="
    )
    opts, given = parse_set(["cv.nosuch=1"])
    with pytest.raises(
        UsageError,
        match=re.escape(
            "--set cv.nosuch=1: predictor cv has no option 'nosuch'; its options: window_s"
        ),
    ):
        validate_predictors(["cv"], opts, given)
