"""`bench check`: run the predictor contract (:mod:`posbench.predictor_tools.contract`) on predictors."""

from __future__ import annotations

import json
import time
from typing import Annotated

import typer

from posbench.cli.common import DataError, UsageError, console, fail, import_from_cwd
from posbench.replay.predictor_setup import model_options, validate_predictors, with_model_aliases

#: registered predictors left out of the default set unless ``--model NAME=PATH`` names them
NEEDS_MODEL = ("lstm-authors",)


def default_names(options: dict[str, dict[str, str]]) -> list[str]:
    """Every registered predictor, but those in :data:`NEEDS_MODEL` only with a model given."""
    from posbench.predictors.registry import available

    return [n for n in available() if n not in NEEDS_MODEL or n in options]


def _factories(specs: list[str], options: dict[str, dict[str, str]]) -> dict:
    """``spec -> factory`` for registered and entry-point names and ``module:Class`` specs
    (imported from the current folder or PYTHONPATH), checked as ``bench run`` checks them."""
    from posbench.predictor_tools.contract import resolve_predictor

    twice = sorted({s for s in specs if specs.count(s) > 1})
    if twice:
        raise UsageError(f"{', '.join(twice)} named more than once")
    import_from_cwd()
    resolved = validate_predictors(specs, options)
    return {s: resolve_predictor(s, resolved.get(s)) for s in specs}


def _print_text(name: str, results: list, seconds: float) -> None:
    from rich.markup import escape

    failed = [r for r in results if not r.passed]
    verdict = (f"all {len(results)} clauses pass" if not failed else
               f"[bold red]{len(failed)} of {len(results)} clauses fail[/]")
    console.print(f"[bold]{escape(name)}[/]: {verdict} ({seconds:.1f} s)", highlight=False,
                  soft_wrap=True)
    width = max(len(r.clause) for r in results)
    for r in results:
        mark = "[green]PASS[/]" if r.passed else "[bold red]FAIL[/]"
        console.print(f"  {mark} {r.clause:<{width}}  {escape(r.evidence)}", highlight=False,
                      soft_wrap=True)


def check(
    predictors: Annotated[list[str] | None, typer.Argument(
        metavar="PREDICTOR",
        help="Registered names (see `bench predictors`; NAME@ALIAS too) or module:Class for a "
             "Predictor subclass of your own, importable from the current folder. Default: every "
             "registered predictor (lstm-authors only with --model lstm-authors=PATH).")] = None,
    model: Annotated[list[str] | None, typer.Option(
        "--model", metavar="NAME=PATH...",
        help="Model file per predictor, e.g. lstm-authors=PATH.onnx or lstm=DIR (after the "
             "predictor names).")] = None,
    gate: Annotated[bool, typer.Option(
        "--gate/--no-gate", help="Check each predictor behind the GPS outlier gate, as `bench run` "
        "runs it by default (--no-gate: the predictor alone).")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of lines.")] = False,
) -> None:
    """Check that predictors obey the streaming contract: reset, NaN before the first fix, no
    look-ahead, finite answers, a straight line and a standstill, query order, pickling,
    determinism, covariance. One line per clause: PASS/FAIL, the clause, its evidence.
    Exit status 0 if every clause passes, 1 if one fails, 2 for a usage error.

    Example: bench check cv mypackage.predictor:MyPredictor
    """
    try:
        options = model_options(model)
        specs = list(predictors or default_names(options))
        left_out = [] if predictors else [n for n in NEEDS_MODEL if n not in specs]
        specs = list(with_model_aliases(specs, options))
        factories = _factories(specs, options)
    except (DataError, UsageError) as e:
        raise fail(str(e)) from None
    from posbench.predictor_tools.contract import check_predictor
    from posbench.predictors.gate import GatedPredictor

    if left_out and not as_json:
        console.print(f"not checked: {', '.join(left_out)} (needs --model NAME=PATH)",
                      highlight=False, soft_wrap=True)
    report, all_passed = [], True
    for spec, factory in factories.items():
        f = (lambda f=factory: GatedPredictor(f())) if gate else factory
        t0 = time.perf_counter()
        if as_json:
            results = check_predictor(f, spec)
        else:
            with console.status(f"checking {spec}..."):
                results = check_predictor(f, spec)
        seconds = time.perf_counter() - t0
        passed = all(r.passed for r in results)
        all_passed &= passed
        report.append({"predictor": spec, "gated": gate, "passed": passed,
                       "seconds": round(seconds, 3),
                       "clauses": [r.to_dict() for r in results]})
        if not as_json:
            _print_text(spec, results, seconds)
    if as_json:
        print(json.dumps({"passed": all_passed, "predictors": report, "not_checked": left_out},
                         indent=2))
    if not all_passed:
        raise typer.Exit(1)
