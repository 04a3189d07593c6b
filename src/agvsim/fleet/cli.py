"""``agvsim fleet SCENARIO``: run the scenario's VDA 5050 vehicles on MQTT."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from agvsim.fleet.transport import BrokerAddress
from agvsim.signals import exit_code, terminate_as_interrupt


def _say(console: Any, text: str) -> None:
    console.print(text, markup=False, highlight=False)


def fleet_command(
    scenario: Path,
    broker: str | None,
    speed: float,
    duration: float | None,
    export_layout: Path | None,
    out: Any,
    err: Any,
    master: bool = False,
    out_dir: Path | None = None,
) -> int:
    """Returns the exit code: 0 done, 1 cannot connect, 2 bad input, 130 interrupted.
    ``master``: run agvsim's master control beside the vehicles (over the broker too) and
    write its summary.json and waiting.png to ``out_dir`` at the end (docs/master.md)."""
    from agvsim.fleet.build import load_layout
    from agvsim.fleet.run import FleetRun
    from agvsim.scenario import ScenarioError, load_scenario
    from agvsim.world.lif import save_lif

    try:
        if broker is not None:
            BrokerAddress.parse(broker)
        sc = load_scenario(scenario)
        if export_layout is not None:
            layout = load_layout(sc, sc._base_dir)
            if layout is None:
                raise ScenarioError(str(scenario), ["the scenario has no 'layout:' block"])
            save_lif(export_layout, [layout], project=sc.name)
            _say(
                out,
                f"wrote {export_layout} ({len(layout.nodes)} nodes, "
                f"{len(layout.edges)} edges, {len(layout.stations)} stations)",
            )
            return 0
        idle_master = master and sc.master is None
        if idle_master:  # nothing to dispatch: it would only send idle vehicles to charge
            master = False
        if master:
            from agvsim.master.mqtt import MasteredFleetRun

            run: FleetRun = MasteredFleetRun(sc, broker, horizon_s=duration)
        else:
            run = FleetRun(sc, broker)
    except (ScenarioError, ValueError) as e:
        _say(err, f"error: {e}")
        return 2
    except OSError as e:
        _say(err, f"error: {e}")
        return 1
    fleet = run.fleet
    try:
        online = run.connect()
        a = run.address
        where = "embedded broker" if run.broker is not None else "broker"
        _say(
            out,
            f"{where} mqtt://{a.host}:{a.port}; {online}/{len(fleet.vehicles)} vehicles "
            f"online (VDA 5050 {fleet.config.version})",
        )
        if online == 0:
            _say(err, f"error: no vehicle could connect to mqtt://{a.host}:{a.port}")
            return 1
        v0 = fleet.vehicles[0]
        _say(
            out,
            f"topics: {fleet.topic(v0, '{order,instantActions,state,visualization,...}')}"
            " (one serial per vehicle)",
        )
        for v in fleet.vehicles:
            _say(
                out,
                f"  {v.cfg.serial:<10} {type(v.spec.model).__name__:<18} on "
                f"{v.last_node.node_id if v.last_node else '-'}",
            )
        if master:
            _say(out, "master: agvsim's (dispatch, SIPP routes, reservations); --no-master: none")
        elif idle_master:
            _say(
                out,
                "master: none - the scenario has no 'master:' block (transport orders), so the "
                "vehicles wait for yours (scenarios/warehouse_operations.yaml has orders)",
            )
        pace = "as fast as it can" if speed <= 0 else f"{speed:g}x real time"
        _say(out, f"running ({pace}); Ctrl-C stops")
        with terminate_as_interrupt():  # SIGTERM stops it like Ctrl-C; the handler is restored
            run.run(duration, speed)
        return 0
    except KeyboardInterrupt as e:
        _say(out, "stopping: vehicles publish OFFLINE")
        return exit_code(e)
    finally:
        run.close()
        if master:
            _report(run, sc, out_dir or Path("runs/fleet") / scenario.stem, out)


def _report(run: Any, sc: Any, out_dir: Path, out: Any) -> None:
    from agvsim.master.report import waiting_heatmap, write_summary

    m = run.master
    t = float(run.fleet.sim.state.t_s)
    s = m.metrics.summary(m, t)
    write_summary(out_dir / "summary.json", sc.name, run.fleet.sim.seed, s)
    waiting_heatmap(out_dir / "waiting.png", m.layout, s["waiting_s_by_node"], sc.name)
    _say(
        out,
        f"{s['orders_completed']} orders completed in {t:.0f} s ({s['orders_per_hour']:g}/h), "
        f"collisions {s['collisions']}, deadlocks {s['deadlocks']}; "
        f"outputs: {out_dir}/summary.json, waiting.png",
    )
