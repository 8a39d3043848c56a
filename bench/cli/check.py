"""``bench check``: run the predictor contract (:mod:`posbench.predictor_tools.contract`) on
predictors."""

from __future__ import annotations

import json
from contextlib import nullcontext
from typing import TYPE_CHECKING, Annotated

import typer

from posbench.cli.options import (
    ConfigOpt,
    GateOpt,
    ModelOpt,
    QuietOpt,
    VerboseOpt,
    import_from_cwd,
)
from posbench.errors import UsageError

if TYPE_CHECKING:
    from posbench.predictor_tools.contract.report import ContractReport

#: registered predictors left out of the default set unless ``--model NAME=PATH`` names them
NEEDS_MODEL = ("lstm-authors",)


def default_names(options: dict[str, dict[str, str]]) -> list[str]:
    """Every registered predictor, but those in :data:`NEEDS_MODEL` only with a model given."""
    from posbench.predictors.registry import available

    return [n for n in available() if n not in NEEDS_MODEL or n in options]


def _print_text(report: ContractReport) -> None:
    from rich.markup import escape

    from posbench.cli.terminal import console

    results = report.clauses
    failed = report.failed
    verdict = (
        f"all {len(results)} clauses pass"
        if not failed
        else f"[bold red]{len(failed)} of {len(results)} clauses fail[/]"
    )
    console.print(
        f"[bold]{escape(report.predictor)}[/]: {verdict} ({report.seconds:.1f} s)",
        highlight=False,
        soft_wrap=True,
    )
    width = max(len(r.clause) for r in results)
    for r in results:
        mark = "[green]PASS[/]" if r.passed else "[bold red]FAIL[/]"
        console.print(
            f"  {mark} {r.clause:<{width}}  {escape(r.evidence)}", highlight=False, soft_wrap=True
        )


def check(
    predictors: Annotated[
        list[str] | None,
        typer.Argument(
            metavar="PREDICTOR",
            help="Registered names (see `bench predictors`; NAME@ALIAS too) or module:Class for a "
            "Predictor subclass of your own, importable from the current folder. Default: every "
            "registered predictor (lstm-authors only with --model lstm-authors=PATH).",
        ),
    ] = None,
    model: ModelOpt = None,
    gate: GateOpt = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of lines.")] = False,
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
) -> None:
    """Check that predictors obey the streaming contract: reset, NaN before the first fix, no
    look-ahead, finite answers, a straight line and a standstill, query order, pickling,
    determinism, covariance. One line per clause: PASS/FAIL, the clause, its evidence.
    Behind the GPS outlier gate by default, as `bench run` runs them (--no-gate: the
    predictor alone). Exit status 0 if every clause passes, 1 if one fails, 2 for a usage
    error.

    Example: bench check cv mypackage.predictor:MyPredictor
    """
    from posbench.checks import parse_pairs
    from posbench.cli.terminal import reporter, say
    from posbench.predictor_tools.contract import check_contract
    from posbench.replay.predictor_options import model_options
    from posbench.replay.predictor_setup import validate_predictors, with_model_aliases

    options = model_options(parse_pairs(model, "--model"))
    specs = list(predictors or default_names(options))
    left_out = [] if predictors else [n for n in NEEDS_MODEL if n not in specs]
    specs = list(with_model_aliases(specs, options))
    twice = sorted({s for s in specs if specs.count(s) > 1})
    if twice:
        raise UsageError(f"{', '.join(twice)} named more than once")
    import_from_cwd()
    resolved = validate_predictors(specs, options)  # every name builds, before any check runs
    if left_out and not as_json:
        say(f"not checked: {', '.join(left_out)} (needs --model NAME=PATH)")
    reports = []
    for spec in specs:
        with reporter().phase(f"checking {spec}...") if not as_json else nullcontext():
            report = check_contract(spec, resolved.get(spec), gate=gate)
        reports.append(report)
        if not as_json:
            _print_text(report)
    passed = all(r.passed for r in reports)
    if as_json:
        print(
            json.dumps(
                {
                    "passed": passed,
                    "predictors": [r.to_dict() for r in reports],
                    "not_checked": left_out,
                },
                indent=2,
            )
        )
    if not passed:
        raise typer.Exit(1)
