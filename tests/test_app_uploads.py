"""What a browser sends: a scenario may use only the files uploaded with it (no absolute path,
no ``..``, no file of the server's disk; an error never tells whether a path exists), uploads
are bounded in size, and a refused upload leaves the running simulation untouched."""

from __future__ import annotations

import io
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml

from agvsim.app.session import Session
from agvsim.app.uploads import Bundle, UploadError, UploadLimits, check_references, plain_name
from agvsim.scenario import ScenarioError, load_scenario
from agvsim.world import loaders
from agvsim.world.grid import OccupancyGrid

ROOM = "\n".join(["#########"] + ["#.......#"] * 7 + ["#########"])
# a map the browser sends: a 7 x 11 room with a pillar
PILLAR = "\n".join(
    ["###########"] + ["#.........#"] * 2 + ["#....#....#"] + ["#.........#"] * 2 + ["###########"]
)


def scenario(world: dict) -> dict:
    robot = {
        "name": "agv",
        "model": "differential",
        "pose": {"x_m": -2.0, "y_m": -1.5},
        "controller": {"type": "script", "steps": [{"duration_s": 100, "twist": [0.2, 0, 0]}]},
    }
    return {"name": "uploaded", "world": world, "robots": [robot]}


@pytest.fixture
def live(tmp_path) -> Session:
    """A session started from a scenario file on disk, as ``agvsim serve FILE`` does, with a
    map file beside it (which a browser's scenario must not be able to read) and a secret."""
    (tmp_path / "room.txt").write_text(ROOM)
    (tmp_path / "secret.txt").write_text(ROOM.replace(".", "#", 3))
    path = tmp_path / "cli.yaml"
    path.write_text(yaml.safe_dump(scenario({"file": "room.txt"})))
    s = Session(load_scenario(path), str(path))
    s.step(10)
    return s


def _zip(files: dict[str, bytes | str]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return buf.getvalue()


def _state(s: Session) -> tuple:
    return (id(s.sim), s.sim.state.t_s, s.sim.state.poses.copy(), yaml.safe_dump(s.config))


def _untouched(s: Session, before: tuple) -> None:
    sim_id, t, poses, config = before
    assert id(s.sim) == sim_id and s.sim.state.t_s == t
    np.testing.assert_array_equal(s.sim.state.poses, poses)
    assert yaml.safe_dump(s.config) == config
    s.step(5)  # and it runs on
    assert s.sim.state.t_s == pytest.approx(t + 5 * s.sim.dt_s)


# ------------------------------------------------------------------------------ file names
@pytest.mark.parametrize("name", ["map.pgm", "maps/floor.yaml", "./map.txt", "a b.png"])
def test_plain_names_are_allowed(name):
    assert plain_name(name, "world.file") == str(Path(name))


@pytest.mark.parametrize(
    "name",
    ["/etc/passwd", "../room.txt", "maps/../../x.pgm", "..", "C:\\maps\\x.png", "a\\..\\b",
     "", "  ", "~/map.pgm", "x\0.txt", "c:x.png", "a" * 300, 5, None],
)  # fmt: skip
def test_names_reaching_outside_the_upload_are_refused(name):
    with pytest.raises(UploadError, match="world.file"):
        plain_name(name, "world.file")


@pytest.mark.parametrize(
    ("ref", "why"),
    [
        ("{tmp}/secret.txt", "is not allowed"),  # an absolute path
        ("../{name}/secret.txt", "is not allowed"),
        ("room.txt", "was not uploaded"),  # beside the command line's scenario, not sent
        ("secret.txt", "was not uploaded"),
    ],
)
def test_a_scenario_cannot_name_a_file_of_the_server(live, tmp_path, ref, why):
    ref = ref.format(tmp=tmp_path, name=tmp_path.name)
    before = _state(live)
    with pytest.raises(UploadError, match="world.file") as info:
        live.load_yaml(yaml.safe_dump(scenario({"file": ref})))
    assert why in str(info.value)
    _untouched(live, before)


def test_a_missing_file_reads_the_same_as_an_existing_one(live, tmp_path):
    """The error for a file that exists on the server and for one that does not differ only
    in the name: it tells nothing about the server's disk."""
    messages = {}
    for ref in ("room.txt", "no_such_map.txt", "maps/room.txt", "maps/no_such.txt"):
        with pytest.raises(UploadError) as info:
            live.load_yaml(yaml.safe_dump(scenario({"file": ref})))
        messages[ref] = str(info.value).replace(ref, "NAME")
    assert len(set(messages.values())) == 1, messages
    assert "was not uploaded with the scenario" in messages["room.txt"]


# ------------------------------------------------------------------------------ bundles
def test_a_zip_brings_its_map(live):
    data = _zip({"scenario.yaml": yaml.safe_dump(scenario({"file": "maps/pillar.txt"})),
                 "maps/pillar.txt": PILLAR})  # fmt: skip
    live.load_upload("lesson.zip", data)
    expected = loaders.parse_text_picture(PILLAR, 1.0, None)
    np.testing.assert_array_equal(live.sim.world.grid.occupied, expected.occupied)
    assert live.sim.state.t_s == 0.0 and live.source == "scenario.yaml"
    # the map is now part of the scenario: nothing refers to the upload's (deleted) files
    assert "file" not in live.config["world"] and "#....#....#" in live.config["world"]["picture"]
    live.apply_robot("agv", live.robot_config("agv"))  # a rebuild needs no file
    np.testing.assert_array_equal(live.sim.world.grid.occupied, expected.occupied)
    assert "file:" not in live.scenario_yaml()


def test_a_ros_map_in_a_zip_and_its_image_name(live, tmp_path):
    grid = OccupancyGrid(loaders.parse_text_picture(PILLAR).occupied, 0.5, (-2.75, -1.75))
    loaders.save_ros_map(grid, tmp_path / "floor.yaml")
    doc = yaml.safe_load((tmp_path / "floor.yaml").read_text())
    pgm = (tmp_path / "floor.pgm").read_bytes()
    sc = scenario({"file": "maps/floor.yaml"})
    sc["robots"][0]["pose"] = {"x_m": -1.5, "y_m": -0.75}
    ok = {
        "scenario.yaml": yaml.safe_dump(sc),
        "maps/floor.yaml": yaml.safe_dump(doc),
        "maps/floor.pgm": pgm,
    }
    live.load_upload("ros.zip", _zip(ok))
    np.testing.assert_array_equal(live.sim.world.grid.occupied, grid.occupied)
    assert live.sim.world.grid.resolution_m == 0.5
    before = _state(live)
    for image in (str(tmp_path / "floor.pgm"), "../floor.pgm", "../../etc/x.pgm", "other.pgm"):
        bad = ok | {"maps/floor.yaml": yaml.safe_dump(doc | {"image": image})}
        with pytest.raises(UploadError, match="key 'image'"):
            live.load_upload("ros.zip", _zip(bad))
        _untouched(live, before)
        before = _state(live)


def test_check_references_reads_no_disk(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "map.txt").write_text(ROOM)  # exists here, but not in the bundle
    with pytest.raises(UploadError, match="not uploaded"):
        check_references("map.txt", Bundle("s.yaml", {"s.yaml": b""}))
    check_references("map.txt", Bundle("s.yaml", {"s.yaml": b"", "map.txt": b""}))
    check_references(None, Bundle("s.yaml", {}))


# ------------------------------------------------------------------------------ limits
def test_an_upload_over_the_size_limit_is_refused_before_parsing(live):
    live.upload_limits = UploadLimits(max_upload_bytes=1000)
    before = _state(live)
    big = yaml.safe_dump(scenario({"picture": ROOM})) + "#" * 1000
    size = f"{len(big.encode()):,}"
    with pytest.raises(UploadError, match=f"{size} bytes is more than the 1,000 bytes") as info:
        live.load_yaml(big)
    assert "--max-upload-mb" in str(info.value)
    with pytest.raises(UploadError, match="1,000 bytes"):
        live.load_grid("maze.txt", (ROOM + "\n") * 20)
    _untouched(live, before)


def test_a_zip_bomb_is_refused_while_it_is_read(live):
    live.upload_limits = UploadLimits(max_upload_bytes=2**20, max_unpacked_bytes=4 * 2**20)
    bomb = _zip({"scenario.yaml": yaml.safe_dump(scenario({"picture": ROOM})),
                 "zeros.bin": b"\0" * (64 * 2**20)})  # fmt: skip
    assert len(bomb) < 2**20  # small as sent
    before = _state(live)
    with pytest.raises(UploadError, match=r"unpack to more than 4,194,304 bytes"):
        live.load_upload("bomb.zip", bomb)
    _untouched(live, before)


def _with_robot(**changes) -> bytes:
    sc = scenario({"picture": ROOM})
    sc["robots"][0].update(changes)
    return yaml.safe_dump(sc).encode()


BAD_UPLOADS = {
    "not a zip": ("x.zip", b"PK\3\4 this is no archive"),
    "an executable": ("run.sh", b"rm -rf /"),
    "a python controller": ("s.yaml", _with_robot(controller={"type": "python", "file": "x.py"})),
    "not YAML": ("s.yaml", b"name: [unclosed\n"),
    "not UTF-8": ("s.yaml", "name: caf\xe9\n".encode("latin-1")),
    "a huge random maze": (
        "s.yaml",
        yaml.safe_dump(scenario({"random": {"rows": 50001, "cols": 50001}})).encode(),
    ),
    "a limits: block raising its own limits": (
        "s.yaml",
        yaml.safe_dump(
            {
                **scenario({"picture": ROOM}),
                "duration_s": 1e6,
                "dt_s": 0.001,
                "limits": {"max_steps": 10**12},
            }  # fmt: skip
        ).encode(),
    ),
    "too many files": ("many.zip", _zip({f"f{i}.txt": "x" for i in range(65)})),
    "two scenarios": ("two.zip", _zip({"a.yaml": "name: a", "b.yaml": "name: b"})),
    "a path in the zip": ("evil.zip", _zip({"../scenario.yaml": "name: a"})),
    "a robot in a wall": ("s.yaml", _with_robot(pose={"x_m": -4.0, "y_m": 0.0})),
}


@pytest.mark.parametrize("case", list(BAD_UPLOADS))
def test_a_refused_upload_leaves_the_running_simulation_untouched(live, case):
    name, data = BAD_UPLOADS[case]
    live.play()
    before = _state(live)
    with pytest.raises((UploadError, ScenarioError)) as info:
        live.load_upload(name, data)
    assert "agvsim-upload-" not in str(info.value)  # no server path in the message
    assert live.playing  # still running
    _untouched(live, before)


@pytest.mark.slow
def test_a_yaml_bomb_upload_is_refused_in_time(tmp_path):
    levels = ['a: &a ["x","x","x","x","x","x","x","x","x","x"]']
    for k in "bcdefghi":  # 10**9 leaves once expanded
        prev = chr(ord(k) - 1)
        levels.append(f"{k}: &{k} [" + ",".join([f"*{prev}"] * 10) + "]")
    bomb = "\n".join(
        ["name: bomb", *levels, "world: {maze: thesis_c1}", "robots:", "  - name: r",
         "    model: differential", "    controller: {type: script, steps: *i}"]
    )  # fmt: skip
    script = textwrap.dedent(
        """
        import sys, yaml
        from agvsim.app.session import Session
        from agvsim.scenario import parse_scenario, ScenarioError
        s = Session(parse_scenario({"name": "x", "world": {"maze": "thesis_c1"},
            "robots": [{"name": "r", "model": "differential"}]}))
        try:
            s.load_yaml(sys.stdin.read())
        except ScenarioError as err:
            print("refused:", err)
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", script], input=bomb, capture_output=True, text=True, timeout=30
    )
    assert proc.returncode == 0 and proc.stdout.startswith("refused:"), proc.stderr


def test_the_server_drops_an_oversized_upload_as_it_starts(live):
    """viser would keep the whole file in memory before the app sees it: an upload declaring
    more than the limit is dropped at its first message (its parts are then ignored)."""
    import asyncio

    from viser import _messages

    from agvsim.app.server import App
    from agvsim.net import free_port

    live.upload_limits = UploadLimits(max_upload_bytes=5000)
    app = App(live, port=free_port())
    try:
        gui = app.server.gui
        button = next(
            uuid
            for uuid, h in gui._gui_input_handle_from_uuid.items()
            if getattr(h, "label", None) == "Load scenario"
        )
        ws = app.server._websock_server

        def start(transfer: str, size: int) -> None:
            message = _messages.FileTransferStartUpload(
                source_component_uuid=button,
                transfer_uuid=transfer,
                filename=f"{transfer}.yaml",
                mime_type="",
                size_bytes=size,
                part_count=1,
            )
            loop = ws._background_event_loop
            asyncio.run_coroutine_threadsafe(ws._handle_incoming_message(0, message), loop).result(
                20
            )

        start("small", 5000)
        start("big", 5001)
        assert "small" in gui._current_file_upload_states  # within the limit: goes on
        assert "big" not in gui._current_file_upload_states  # dropped at once
    finally:
        app.stop()
