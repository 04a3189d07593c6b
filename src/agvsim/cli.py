"""The ``agvsim`` command."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from agvsim import __version__

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="agvsim: a fast simulator of AGVs (wheeled mobile robots).",
)
err = Console(stderr=True, soft_wrap=True)
out = Console(soft_wrap=True)


def _fail(label: str, message: object, style: str = "red") -> None:
    """Print a user-facing error: the label styled, the message verbatim (no markup)."""
    err.print(f"{label}:", style=style, end=" ")
    err.print(str(message), markup=False, highlight=False)


def _version(value: bool) -> None:
    if value:
        out.print(f"agvsim {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print version.")
    ] = False,
) -> None:
    """Simulate AGVs: kinematic models, mazes, lidar, controllers, scenarios."""


@app.command()
def serve(
    scenario: Annotated[
        Path | None, typer.Argument(help="Scenario YAML file (default: the thesis maze).")
    ] = None,
    host: Annotated[
        str, typer.Option(help="Interface to listen on; 0.0.0.0 opens it to your network.")
    ] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="Port of the app.")] = 8080,
    play: Annotated[bool, typer.Option("--play", help="Start running at once.")] = False,
    out_dir: Annotated[
        Path, typer.Option("--out", help="Output folder of the app's videos (video_1, ...).")
    ] = Path("runs/app"),
    max_upload_mb: Annotated[
        float,
        typer.Option(help="Most MB a file sent from the browser may have.", min=0.001, max=4096),
    ] = 10.0,
    broker: Annotated[
        str | None,
        typer.Option(
            help="MQTT broker of a scenario's VDA 5050 vehicles, mqtt://HOST:PORT "
            "(default: an embedded one on 127.0.0.1)."
        ),
    ] = None,
    no_master: Annotated[
        bool,
        typer.Option(
            "--no-master",
            help="VDA 5050 vehicles wait for your master's orders (default: agvsim's master "
            "control runs the scenario's master: block).",
        ),
    ] = False,
) -> None:
    """Open the browser app: 3D view, the robot mask, run controls, video, maze editor,
    plots. Only a browser that opens the printed address (with its token) gets in. A
    scenario with a vda5050: block runs its robots as VDA 5050 vehicles on MQTT."""
    from agvsim.scenario import ScenarioError

    try:
        from agvsim.app.fleet_view import BrokerError
        from agvsim.app.server import serve as serve_app
    except ImportError as e:  # pragma: no cover - viser is a dependency
        _fail("error", f"the browser app needs viser ({e}); pip install viser")
        raise typer.Exit(1) from None
    from agvsim.fleet.transport import BrokerAddress

    if broker is not None:
        try:
            BrokerAddress.parse(broker)
        except ValueError as e:
            _fail("error", e)
            raise typer.Exit(2) from None

    def ready(a) -> None:
        out.print(f"agvsim app on [bold]{a.url}[/bold]  (Ctrl-C stops it)", soft_wrap=True)
        for line in getattr(a.session, "banner", list)():  # a VDA 5050 fleet: broker, topics
            out.print(line, markup=False, highlight=False, soft_wrap=True)
        if host not in ("127.0.0.1", "localhost", "::1"):
            err.print(
                f"warning: listening on {host}: anyone on your network can open it", style="yellow"
            )

    out.print(
        "preparing the app (the first run compiles the simulation kernels: about 30 s)...",
        highlight=False,
    )
    try:
        serve_app(
            scenario,
            host=host,
            port=port,
            play=play,
            on_ready=ready,
            out_dir=out_dir,
            notify=lambda m: out.print(m, markup=False, highlight=False),
            max_upload_bytes=int(max_upload_mb * 2**20),
            broker=broker,
            master=not no_master,
        )
    except ScenarioError as e:
        _fail("error", e)
        raise typer.Exit(2) from None
    except BrokerError as e:
        _fail("error", e)
        raise typer.Exit(1) from None
    except OSError as e:
        _fail("error", f"cannot listen on {host}:{port}: {e}")
        raise typer.Exit(1) from None


@app.command()
def replay(
    recording: Annotated[Path, typer.Argument(help="A run.mcap written by `agvsim run`.")],
    host: Annotated[str, typer.Option(help="Interface to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="Port of the player.")] = 8080,
    speed: Annotated[float, typer.Option(help="Playback speed (recorded s per s).")] = 1.0,
    paused: Annotated[bool, typer.Option("--paused", help="Start paused.")] = False,
) -> None:
    """Play a recording (run.mcap) in the browser: play, pause, speed and a time slider."""
    from agvsim.app.replay import replay as replay_app
    from agvsim.record.mcap_reader import RecordingError

    def ready(a) -> None:
        out.print(
            f"agvsim replay of {recording} on [bold]{a.url}[/bold]  (Ctrl-C stops it)",
            soft_wrap=True,
        )

    try:
        replay_app(recording, host=host, port=port, speed=speed, play=not paused, on_ready=ready)
    except (RecordingError, ValueError) as e:
        _fail("error", e)
        raise typer.Exit(2) from None
    except OSError as e:
        _fail("error", f"cannot listen on {host}:{port}: {e}")
        raise typer.Exit(1) from None


def _finite_duration(value: float | None) -> float | None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise typer.BadParameter(f"{value!r} is not allowed (a finite number of seconds > 0)")
    return value


LIMIT_HELP = (
    "Raise a limit, NAME=VALUE (repeatable): max_steps, max_robots, max_grid_cells, "
    "max_camera_pixels_per_s, max_lidar_rays_per_s, yaml_max_bytes, yaml_max_nodes, "
    "yaml_max_depth (docs/scenario.md, 'Limits')."
)


def _load(scenario: Path, limit: list[str] | None, duration: float | None = None):
    """The validated scenario (limits applied; a --duration checked against max_steps);
    exits with code 2 and a clear message when it is not valid."""
    from agvsim.scenario import ScenarioError, load_scenario
    from agvsim.scenario_limits import Limits, steps_of

    try:
        limits = Limits.from_options(limit)
    except ValueError as e:
        _fail("error", e)
        raise typer.Exit(2) from None
    try:
        sc = load_scenario(scenario, limits)
        if duration is not None:
            steps_of(duration, sc.dt_s, sc._limits, "--duration")
    except ScenarioError as e:
        _fail("error", e)
        raise typer.Exit(2) from None
    except ValueError as e:
        _fail("error", f"{scenario}: {e}")
        raise typer.Exit(2) from None
    return sc


@app.command()
def run(
    scenario: Annotated[Path, typer.Argument(help="Scenario YAML file.")],
    duration: Annotated[
        float | None,
        typer.Option(help="Simulated seconds (overrides file).", callback=_finite_duration),
    ] = None,
    seed: Annotated[
        int | None, typer.Option(help="Random seed (overrides file).", min=0, max=2**63 - 1)
    ] = None,
    out_dir: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("runs/latest"),
    record_every: Annotated[
        int, typer.Option(help="Write a trajectory row every N steps.", min=1)
    ] = 1,
    no_plot: Annotated[bool, typer.Option("--no-plot", help="Skip plot.png.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
    no_mcap: Annotated[
        bool, typer.Option("--no-mcap", help="Skip run.mcap (the ROS 2 recording).")
    ] = False,
    video: Annotated[
        bool, typer.Option("--video", help="Also write top.mp4 (and one MP4 per camera).")
    ] = False,
    limit: Annotated[list[str] | None, typer.Option(help=LIMIT_HELP, metavar="NAME=VALUE")] = None,
    controller_time_limit: Annotated[
        float,
        typer.Option(
            help="Wall-clock seconds one step of a python controller may take; 0: no limit."
        ),
    ] = 10.0,
) -> None:
    """Run a scenario headless; write summary.json, trajectory.csv, plot.png and run.mcap
    (ROS 2 recording, see docs/recording.md) to --out."""
    from agvsim.runner import run_scenario
    from agvsim.scenario import ScenarioError
    from agvsim.signals import Terminated, exit_code
    from agvsim.sim.engine import ControllerError

    progress = Progress(
        TextColumn("[bold]simulating" + (" + video" if video else "")),
        BarColumn(),
        TextColumn("{task.fields[t]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err,
        disable=quiet,
        transient=False,
    )
    # before the first tick the kernels load (a first run compiles them: 15-60 s, once)
    task = progress.add_task("run", total=1.0, t="preparing (first run compiles kernels)")

    def tick(t: float, total: float) -> None:
        progress.update(task, completed=t / total, t=f"{t:7.1f} / {total:.1f} s")

    sc = _load(scenario, limit, duration)
    try:
        with progress:
            data = run_scenario(
                sc,
                out_dir,
                duration,
                seed,
                record_every,
                not no_plot,
                tick,
                record_mcap=not no_mcap,
                video=video,
                controller_time_limit_s=controller_time_limit or None,
            )
    except ScenarioError as e:
        _fail("error", e)
        raise typer.Exit(2) from None
    except ControllerError as e:
        _fail("controller error", f"{e}\noutputs so far written to {out_dir}")
        raise typer.Exit(1) from None
    except KeyboardInterrupt as e:
        how = " (SIGTERM)" if isinstance(e, Terminated) else ""
        _fail(f"interrupted{how}", f"outputs so far written to {out_dir}", "yellow")
        raise typer.Exit(exit_code(e)) from None
    r = data["run"]
    out.print(
        f"simulated {r['simulated_time_s']:.1f} s in {r['wall_time_s']:.2f} s "
        f"(real-time factor {r['real_time_factor']:.1f}x)"
    )
    first = r.get("first_step_s")
    if first is not None and first > 5.0 and first > 0.3 * r["wall_time_s"]:
        out.print(
            f"  of which {first:.1f} s before the first step ended: numba compiled the "
            "simulator's kernels for this machine (cached: the next run starts at once)"
        )
    for rb in data["robots"]:
        p = rb["final_pose"]
        out.print(
            f"  {rb['name']:<12} {rb['model']:<12} distance {rb['distance_m']:7.2f} m  "
            f"collisions {rb['wall_collisions']:2d} wall {rb['robot_collisions']:2d} robot  "
            f"final ({p['x_m']:.2f}, {p['y_m']:.2f}, "
            f"{p['theta_rad']:.2f} rad)"
        )
        if rb.get("controller"):
            out.print(f"  {'':<12} {_shown(rb['controller'])}")
    for name, values in data.get("metrics", {}).items():
        out.print(f"  metric {name}: {_shown(values)}")
    for name, sc in data.get("slam", {}).items():
        err_m = sc.get("trajectory_error", {}).get("mean_m")
        iou = sc.get("map", {}).get("tolerant", {}).get("iou")
        out.print(
            f"  slam {name}: map IoU {iou:.3f}, mean path error {err_m:.3f} m (in {sc['dir']}/)"
            if iou is not None and err_m is not None
            else f"  slam {name}: in {sc['dir']}/"
        )
    if r["status"] != "completed":
        out.print(f"  status: {r['status']}")
    from agvsim.dynamics.vehicle import newton_warning

    unconverged = newton_warning(data.get("dynamics", []))
    if unconverged is not None:  # once a run (agvsim.dynamics)
        _fail("warning", unconverged, style="yellow")
    written = ["summary.json", "trajectory.csv"] + ([] if no_plot else ["plot.png"])
    written += ["wheels.png"] if data.get("dynamics") and not no_plot else []
    written += [] if no_mcap else ["run.mcap"]
    written += sorted(p.name for p in Path(out_dir).glob("*.mp4"))
    written += [f"{s['dir']}/" for s in data.get("slam", {}).values()]
    out.print(f"outputs in {out_dir}/: " + ", ".join(written))


def _shown(values: dict) -> str:
    """``key value, ...`` with floats to 2 decimals."""
    return ", ".join(
        f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}" for k, v in values.items()
    )


@app.command()
def fleet(
    scenario: Annotated[Path, typer.Argument(help="Scenario YAML with a 'vda5050:' block.")],
    broker: Annotated[
        str | None,
        typer.Option(help="External broker mqtt://HOST:PORT (default: an embedded one)."),
    ] = None,
    speed: Annotated[
        float, typer.Option(help="Simulated seconds per real second (0: as fast as possible).")
    ] = 1.0,
    duration: Annotated[
        float | None, typer.Option(help="Stop after this many simulated seconds.")
    ] = None,
    export_layout: Annotated[
        Path | None, typer.Option(help="Write the scenario's layout as a LIF file and exit.")
    ] = None,
    no_master: Annotated[
        bool, typer.Option("--no-master", help="No master: leave the vehicles to an external one.")
    ] = False,
    out_dir: Annotated[
        Path | None, typer.Option("--out", help="Master outputs (default: runs/fleet/SCENARIO).")
    ] = None,
) -> None:
    """Run the scenario's VDA 5050 vehicles on MQTT with agvsim's master control, or for an
    external master (--no-master); docs/fleet.md, docs/master.md."""
    from agvsim.fleet.cli import fleet_command

    code = fleet_command(
        scenario, broker, speed, duration, export_layout, out, err, not no_master, out_dir
    )
    if code:
        raise typer.Exit(code)


@app.command()
def validate(
    scenario: Annotated[Path, typer.Argument(help="Scenario YAML file.")],
    limit: Annotated[list[str] | None, typer.Option(help=LIMIT_HELP, metavar="NAME=VALUE")] = None,
) -> None:
    """Check a scenario file (schema, map, robot placement, limits, metrics, SLAM) without
    running it."""
    from agvsim.runner import build_metrics, build_slams
    from agvsim.scenario import ScenarioError, build

    sc = _load(scenario, limit)
    try:
        if sc.vda5050 is None:
            sim = build(sc)
            build_metrics(sc, sim, str(scenario))  # what `run` sets up before its first step
            build_slams(sc, sim, str(scenario))
        else:  # vehicles start on layout nodes
            from agvsim.fleet.build import build_fleet

            fleet = build_fleet(sc)
            if sc.master is not None:  # station and vehicle names of the master's block
                from agvsim.master.run import build_master

                build_master(sc, fleet, sc.seed, sc.duration_s)
    except ScenarioError as e:
        _fail("error", e)
        raise typer.Exit(2) from None
    out.print(f"{scenario}: valid")


@app.command()
def sweep(
    sweep_file: Annotated[Path, typer.Argument(help="Sweep YAML file.", metavar="SWEEP.yaml")],
    out_dir: Annotated[
        Path | None, typer.Option("--out", help="Output folder (default: the file's out:).")
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="Local processes, or Ray CPUs (default: one per CPU).")
    ] = None,
    ray: Annotated[
        bool, typer.Option("--ray", help="Run on Ray (pip install 'agvsim\\[ray]'), started here.")
    ] = False,
    ray_address: Annotated[
        str | None,
        typer.Option(help="Run on the Ray cluster at ADDRESS (auto, ray://host:10001); --ray."),
    ] = None,
    limit: Annotated[int | None, typer.Option(help="Run at most N new runs, then stop.")] = None,
    no_plot: Annotated[bool, typer.Option("--no-plot", help="Skip the plots.")] = False,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="Check, list; run nothing.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
) -> None:
    """Run a grid of scenario variations x seeds (resumable); write results.parquet/.csv and
    comparison plots."""
    from agvsim.experiments.commands import sweep_command
    from agvsim.signals import terminate_as_interrupt

    with terminate_as_interrupt():  # SIGTERM stops the sweep as Ctrl-C does
        code = sweep_command(
            sweep_file,
            out_dir,
            workers,
            ray,
            ray_address,
            limit,
            not no_plot,
            quiet,
            dry_run,
            out,
            err,
        )
    raise typer.Exit(code)


@app.command()
def grade(
    controllers: Annotated[
        list[Path], typer.Argument(help="Student controller file(s).", metavar="CONTROLLER.py...")
    ],
    suite: Annotated[Path, typer.Option("--suite", help="Grading suite YAML file.")],
    out_dir: Annotated[
        Path | None, typer.Option("--out", help="Output folder (default: runs/grades/SUITE).")
    ] = None,
    name: Annotated[
        str | None, typer.Option(help="Function or class to grade (default: the suite's).")
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
) -> None:
    """Grade controllers on a suite of tasks; print a score table, write grades.csv/json."""
    from agvsim.experiments.commands import grade_command
    from agvsim.signals import terminate_as_interrupt

    with terminate_as_interrupt():  # SIGTERM stops the grading as Ctrl-C does
        code = grade_command(controllers, suite, out_dir, name, quiet, out, err)
    raise typer.Exit(code)


@app.command()
def bench(
    quick: Annotated[bool, typer.Option("--quick", help="Short version (under a minute).")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    app_only: Annotated[
        bool,
        typer.Option("--app", help="Only the browser app: 10 robots, 240-beam lidars, frames/s."),
    ] = False,
    fleet_only: Annotated[
        bool,
        typer.Option("--fleet", help="Only the VDA 5050 fleet on MQTT (docs/fleet.md)."),
    ] = False,
) -> None:
    """Measure ray-casting throughput, steps/s and real-time factor for 1, 100, 1000 robots
    (or, with --app, the browser app's frame rate)."""
    if fleet_only:
        from agvsim.fleet.bench import fleet_benchmark

        result = fleet_benchmark(quick=quick, log=None if as_json else err.print)
    elif app_only:
        from agvsim.bench_app import run_app_benchmark

        result = run_app_benchmark(
            seconds=5.0 if quick else 10.0, log=None if as_json else err.print
        )
    else:
        from agvsim.bench import run_benchmarks

        result = run_benchmarks(quick=quick, log=None if as_json else err.print)
    if as_json:
        sys.stdout.write(json.dumps(result) + "\n")
    else:
        out.print_json(json.dumps(result))


@app.command()
def slam(
    target: Annotated[
        str,
        typer.Argument(
            help="A laser log to map (CARMEN .clf / .clf.gz), or 'eval' TRAJECTORY RELATIONS, "
            "or 'optimize' GRAPH.g2o.",
            metavar="LOG | eval | optimize",
        ),
    ],
    files: Annotated[list[Path] | None, typer.Argument(help="Files of eval / optimize.")] = None,
    out_dir: Annotated[
        Path | None, typer.Option("--out", help="Output folder (mapping) or file (optimize).")
    ] = None,
    max_scans: Annotated[
        int | None, typer.Option(help="Stop after this many scans (a slice of the log).")
    ] = None,
    robust: Annotated[str, typer.Option(help="optimize: none, huber or cauchy.")] = "none",
    robot: Annotated[
        str | None,
        typer.Option(help="Mapping a run.mcap: the robot whose lidar to use (default: the first)."),
    ] = None,
    sensor: Annotated[
        str | None,
        typer.Option(help="Mapping a run.mcap: that robot's lidar (default: its first)."),
    ] = None,
    long_corridors: Annotated[
        bool,
        typer.Option(
            "--long-corridors/--point-samples",
            help="Mapping: spread far, edge-on wall samples along their wall and leave "
            "glimpses through doors out of the live map, so corridors that run beyond the "
            "scanner's reach do not hold tracking back (the default, while the scans come "
            "densely); --point-samples: every return a bump, the published figures' setting "
            "(docs/slam.md).",
        ),
    ] = True,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
) -> None:
    """2-D graph SLAM: map a laser log (writes trajectory.txt, map.pgm/.yaml/.png to --out),
    score a trajectory (Kuemmerle et al. relations), or optimise a g2o pose graph."""
    from agvsim.slam.eval_cli import SlamCommandError, eval_command, optimize_g2o_command

    files = files or []
    try:
        if target == "eval":
            if len(files) != 2:
                raise SlamCommandError("usage: agvsim slam eval TRAJECTORY RELATIONS")
            out.print(eval_command(files[0], files[1]), markup=False, highlight=False)
            return
        if target == "optimize":
            if len(files) != 1:
                raise SlamCommandError("usage: agvsim slam optimize GRAPH.g2o [--out FILE]")
            text = optimize_g2o_command(files[0], out_dir, robust, 100)
            out.print(text, markup=False, highlight=False)
            return
        if files:
            raise SlamCommandError(f"mapping takes one log; got extra arguments {files}")
        _slam_log(
            Path(target),
            out_dir or Path("runs/slam"),
            max_scans,
            quiet,
            robot,
            sensor,
            long_corridors,
        )
    except SlamCommandError as e:
        _fail("error", e)
        raise typer.Exit(2) from None


def _slam_log(
    log: Path,
    out_dir: Path,
    max_scans: int | None,
    quiet: bool,
    robot: str | None = None,
    sensor: str | None = None,
    long_corridors: bool = True,
) -> None:
    from agvsim.record.scan_log import open_scan_log
    from agvsim.slam.carmen import CarmenFormatError
    from agvsim.slam.graph_slam import SlamConfig
    from agvsim.slam.offline import run_offline

    if not log.is_file():
        _fail("error", f"{log}: no such log file")
        raise typer.Exit(2)
    try:
        with Progress(
            TextColumn("[bold]SLAM[/bold] {task.fields[name]}"),
            BarColumn(),
            TextColumn("{task.completed}/{task.total} scans"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=err,
            disable=quiet,
        ) as bar:
            task = bar.add_task("slam", total=None, name=log.name)
            result = run_offline(
                open_scan_log(log, robot, sensor),
                out_dir,
                config=None if long_corridors else SlamConfig.point_samples(),
                max_scans=max_scans,
                progress=lambda done, total: bar.update(task, completed=done, total=total),
            )
    except (CarmenFormatError, ValueError) as e:
        _fail("error", e)
        raise typer.Exit(2) from None
    r = result
    for warning in r.warnings:
        _fail("warning", warning, style="yellow")
    out.print(
        f"{r.n_scans} scans, {r.n_keyframes} keyframes, {r.n_submaps} submaps, "
        f"{r.n_loop_closures} loop closures; {r.log_duration_s:.0f} s of data in "
        f"{r.processing_s:.1f} s ({r.realtime_factor:.1f}x real time)\n"
        f"wrote {r.trajectory_path}, {r.map_yaml_path} (+ .pgm), {r.map_png_path}",
        markup=False,
        highlight=False,
    )


@app.command()
def statechart(
    controller: Annotated[
        str, typer.Argument(help="A built-in chart (avoid) or FILE.py[:NAME] defining one.")
    ],
    fmt: Annotated[str, typer.Option("--format", help="mermaid or dot (Graphviz).")] = "mermaid",
) -> None:
    """Print a state-machine controller's diagram as Mermaid or Graphviz text."""
    from agvsim.control.statechart import resolve, to_dot, to_mermaid

    if fmt not in ("mermaid", "dot"):
        _fail("error", f"--format must be 'mermaid' or 'dot', got {fmt!r}")
        raise typer.Exit(2)
    try:
        sm = resolve(controller)
    except (ValueError, OSError) as e:
        _fail("error", e)
        raise typer.Exit(2) from None
    sys.stdout.write((to_mermaid(sm) if fmt == "mermaid" else to_dot(sm)) + "\n")


@app.command()
def models() -> None:
    """List the kinematic models and their parameters (default, allowed values, meaning)."""
    from dataclasses import fields

    from agvsim.kinematics import MODELS
    from agvsim.kinematics.params import bounds_of, choices_of

    for name, cls in MODELS.items():
        wheels: tuple[str, ...] = getattr(cls, "wheel_names", ())
        out.print(f"[bold]{name}[/bold] ({cls.__name__}): wheels {', '.join(wheels)}")
        choices = choices_of(cls)
        for f in fields(cls):
            default = f"{f.default:.6g}" if isinstance(f.default, float) else f"{f.default}"
            bounds = bounds_of(f)
            allowed = (
                " | ".join(choices[f.name])
                if f.name in choices
                else bounds.describe()
                if bounds is not None
                else ""
            )
            doc = f.metadata.get("doc", "")
            out.print(f"  {f.name} = {default}  ({allowed}){'  ' + doc if doc else ''}")


if __name__ == "__main__":  # pragma: no cover
    app()
