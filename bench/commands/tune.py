"""`bench tune`: grid-search a filter's noise on development drives."""

from __future__ import annotations

from typing import Annotated

import typer

from bench.commands.common import (
    WORKER_DIED,
    DataError,
    DataOpt,
    UsageError,
    command_line,
    console,
    fail,
    load_drives,
)
from bench.options import check_at_least, check_choice, check_data_paths


def tune(
    predictor: Annotated[str, typer.Argument(
        metavar="PREDICTOR", help="Predictor to tune (kf or ekf).")],
    gps_profile: Annotated[str, typer.Option(
        metavar="PROFILE",
        help="GPS condition to tune for: none, rtk, consumer (synthetic development drives, "
             "seeds 1000+) or native (give --data: the development routes).")] = "rtk",
    data: DataOpt = None,
    drives: Annotated[int, typer.Option(
        metavar="N", help="Synthetic development drives per route type.")] = 1,
    workers: Annotated[int, typer.Option(metavar="N", help="Parallel processes.")] = 2,
    save: Annotated[bool, typer.Option(help="Write the winner to predictors/tuned.json.")] = True,
) -> None:
    """Grid-search a filter's noise parameters on development drives (never evaluation drives)."""
    from concurrent.futures.process import BrokenProcessPool

    from bench.config import GPS_PROFILES
    from bench.tune import GRIDS, grid_for, grid_search, save_tuned

    if predictor not in GRIDS:
        raise fail(f"no tuning grid for {predictor!r}; tunable: {', '.join(GRIDS)}")
    try:
        check_choice(gps_profile, GPS_PROFILES, "--gps-profile")
        check_at_least(drives, 1, "--drives")
        check_at_least(workers, 1, "--workers")
        if data and gps_profile != "native":
            raise UsageError("--data is for --gps-profile native (the other profiles tune on "
                             "synthetic development drives)")
        check_data_paths(data)
        if gps_profile == "native":
            if not data:
                raise UsageError("--gps-profile native tunes on recorded fixes: give --data PATH...")
            dev = load_drives(data, "enu", None)
            source = "development routes " + ", ".join(str(p) for p in data)
        else:
            from scenarios.synthetic import default_drives

            dev = [d for s in range(1000, 1000 + drives) for d in default_drives(seed=s)]
            source = f"synthetic development drives, seeds 1000-{999 + drives}"
        grid = grid_for(predictor, gps_profile)
        n = len(list(__import__("itertools").product(*list(grid.values())[:2]))) + sum(
            len(v) for v in list(grid.values())[2:])
        from rich.progress import Progress

        with Progress(console=console) as prog:
            task = prog.add_task(f"tuning {predictor} ({gps_profile})", total=n)
            best, trials = grid_search(predictor, dev, gps_profile, grid, workers=workers,
                                       on_step=lambda p, v: prog.update(task, advance=1))
    except (DataError, UsageError) as e:
        raise fail(str(e)) from None
    except BrokenProcessPool:
        raise fail(WORKER_DIED) from None
    best_val = min(v for _, v in trials)
    console.print(f"best {best} -> future+now mean error {best_val:.4f} m over {len(dev)} drives")
    if save:
        command = command_line()
        save_tuned(predictor, gps_profile, best,
                   f"`{command}`: {source}; objective mean future + mean now error "
                   f"{best_val:.4f} m; {len(trials)} trials")
        console.print("saved to predictors/tuned.json")
