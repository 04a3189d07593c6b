"""World building: thesis mazes, map readers/writers, upsampling, random mazes, tiling."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from agvsim.world.grid import OccupancyGrid
from agvsim.world.loaders import (
    MapFormatError,
    format_text_picture,
    grid_from_matrix,
    load_csv,
    load_image,
    load_map,
    load_ros_map,
    load_text,
    parse_text_picture,
    save_csv,
    save_png,
    save_ros_map,
    save_text,
)
from agvsim.world.mazes import (
    THESIS_MAZES,
    free_cells_connected,
    random_maze,
    thesis_maze,
    tile,
    upsample,
)

# The thesis matrices, typed in from the brief independently of the packaged text pictures.
FIG16 = """
11111111111111111111
10010000000010000001
10010000000010000001
10011111110011111001
10000000000010000001
10000000000010000001
10011111111110000001
10010000000000000001
10010000000000000001
10010000000011111111
10010000000010000001
10010000000010000001
10010000000010011001
10010000100010001001
10010000100010001001
10011111100010001001
10000000000011111001
10000000000000000001
10000000000000000001
11111111111111111111
"""
C1 = """
11111111111111111111
10010000000010000001
10010000000010000001
10011111100011110001
10000000000010000001
10000000000010000001
10011111111110000001
10010000000000000001
10010000000000000001
10000000000000000001
10000000000000000001
10011000000111111111
10001000000100000001
10001000000100000001
10001000000100001001
10001100000100001001
10000000000111111001
10000000000000000001
10000000000000000001
11111111111111111111
"""


def _matrix(digits: str) -> np.ndarray:
    return np.array([[ch == "1" for ch in line] for line in digits.split()], dtype=bool)


# ------------------------------------------------------------------------------ thesis mazes
@pytest.mark.parametrize(("name", "digits"), [("thesis_fig16", FIG16), ("thesis_c1", C1)])
def test_thesis_maze_matches_thesis_matrix(name: str, digits: str) -> None:
    g = thesis_maze(name)
    assert g.occupied.shape == (20, 20)
    np.testing.assert_array_equal(g.occupied, _matrix(digits))
    assert g.resolution_m == 1.0
    assert g.extent_m == (-10.0, 10.0, -10.0, 10.0)
    assert free_cells_connected(g)
    assert set(THESIS_MAZES) == {"thesis_fig16", "thesis_c1"}


def test_thesis_maze_cells_and_world_positions() -> None:
    g = thesis_maze("thesis_fig16")
    assert g.occupied[0, 0]
    assert g.cell_center(0, 0) == (-9.5, 9.5)
    assert not g.occupied[1, 1]
    assert not g.is_occupied_at(-8.5, 8.5)
    assert g.is_occupied_at(-9.5, 9.5)
    row3 = [1, 0, 0, 1, 1, 1, 1, 1, 1, 1, 0, 0, 1, 1, 1, 1, 1, 0, 0, 1]
    assert g.occupied[3].astype(int).tolist() == row3
    # row 3, col 10 is the gap in that wall: centre x = -10 + 10.5, y = 10 - 3.5
    assert not g.is_occupied_at(0.5, 6.5)
    assert g.is_occupied_at(-0.5, 6.5)
    # App. C.1 row 9 is an open east-west corridor
    c1 = thesis_maze("thesis_c1")
    assert c1.occupied[9].astype(int).tolist() == [1] + [0] * 18 + [1]


def test_thesis_maze_resolution_scales_extent() -> None:
    g = thesis_maze("thesis_c1", resolution_m=0.5)
    assert g.extent_m == (-5.0, 5.0, -5.0, 5.0)
    assert g.cell_center(0, 0) == (-4.75, 4.75)


def test_unknown_thesis_maze_lists_names() -> None:
    with pytest.raises(ValueError, match="thesis_fig16.*thesis_c1"):
        thesis_maze("fig17")


# ------------------------------------------------------------------------------ round trips
SMALL = [[1, 1, 1, 1, 1], [1, 0, 0, 1, 1], [1, 1, 0, 0, 0]]
RES, ORIGIN = 0.05, (1.25, -3.5)


def test_grid_from_matrix_accepts_bools_and_centres() -> None:
    g = grid_from_matrix([[True, False], [False, False]], resolution_m=2.0)
    assert g.occupied.tolist() == [[True, False], [False, False]]
    assert g.extent_m == (-2.0, 2.0, -2.0, 2.0)
    assert g.is_occupied_at(-1.0, 1.0) and not g.is_occupied_at(1.0, -1.0)
    g2 = grid_from_matrix(np.array(SMALL), RES, ORIGIN)
    assert g2.origin_xy_m == ORIGIN and g2.occupied.shape == (3, 5)


@pytest.mark.parametrize(
    ("save", "load", "name"),
    [
        (save_text, load_text, "m.txt"),
        (save_csv, load_csv, "m.csv"),
        (save_png, load_image, "m.png"),
    ],
)
def test_picture_round_trip(tmp_path: Path, save, load, name: str) -> None:
    g = grid_from_matrix(SMALL, RES, ORIGIN)
    path = save(g, tmp_path / name)
    for back in (load(path, RES, ORIGIN), load_map(path, RES, ORIGIN)):
        np.testing.assert_array_equal(back.occupied, np.array(SMALL, dtype=bool))
        assert back.resolution_m == RES
        assert back.origin_xy_m == ORIGIN


def test_ros_round_trip_keeps_origin_and_resolution(tmp_path: Path) -> None:
    g = random_maze(5, 7, 3, resolution_m=0.05)
    g = OccupancyGrid(g.occupied, 0.05, (-12.345678901234, 0.1 + 0.2))
    yaml_path = save_ros_map(g, tmp_path / "warehouse.yaml")
    assert (tmp_path / "warehouse.pgm").is_file()
    for back in (load_ros_map(yaml_path), load_map(yaml_path)):
        np.testing.assert_array_equal(back.occupied, g.occupied)
        assert back.resolution_m == g.resolution_m
        assert back.origin_xy_m == g.origin_xy_m


def _write_ros(tmp_path: Path, pixels: np.ndarray, **overrides: object) -> Path:
    Image.fromarray(pixels.astype(np.uint8)).save(tmp_path / "img.pgm")
    keys = {
        "image": "img.pgm",
        "resolution": 0.5,
        "origin": "[2.0, -1.0, 0.0]",
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    keys.update(overrides)
    text = "".join(f"{k}: {v}\n" for k, v in keys.items() if v is not None)
    path = tmp_path / "map.yaml"
    path.write_text(text)
    return path


def test_ros_map_puts_pixel_at_world_position(tmp_path: Path) -> None:
    # 3 rows x 4 cols, 0.5 m pixels, lower-left corner at (2, -1): the map spans x in [2, 4],
    # y in [-1, 0.5]. Image row 0, col 3 (black) is the north-east cell: centre (3.75, 0.25).
    px = np.full((3, 4), 254)
    px[0, 3] = 0
    px[2, 0] = 205  # map_saver's "unknown": p = 50/255 = 0.196 > free_thresh, < occupied_thresh
    g = load_ros_map(_write_ros(tmp_path, px))
    assert g.extent_m == (2.0, 4.0, -1.0, 0.5)
    assert g.is_occupied_at(3.75, 0.25)
    assert not g.is_occupied_at(3.25, 0.25) and not g.is_occupied_at(3.75, -0.25)
    assert g.is_occupied_at(2.25, -0.75)  # unknown -> occupied by default
    g_free = load_ros_map(tmp_path / "map.yaml", unknown_is_occupied=False)
    assert not g_free.is_occupied_at(2.25, -0.75)
    assert int(g.occupied.sum()) == 2 and int(g_free.occupied.sum()) == 1


def test_ros_map_negate_raw_and_relative_image(tmp_path: Path) -> None:
    px = np.array([[0, 254]])
    g = load_ros_map(_write_ros(tmp_path, px, negate=1))
    assert g.occupied.tolist() == [[False, True]]
    raw = np.array([[0, 100, 255, 50]])  # free, occupied, unknown, unknown (0.5 in between)
    g = load_ros_map(_write_ros(tmp_path, raw, mode="raw"), unknown_is_occupied=False)
    assert g.occupied.tolist() == [[False, True, False, False]]
    sub = tmp_path / "maps"
    sub.mkdir()
    Image.fromarray(np.array([[0, 254]], dtype=np.uint8)).save(sub / "floor.png")
    (tmp_path / "nested.yaml").write_text(
        "image: maps/floor.png\nresolution: 1\norigin: [0, 0, 0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    assert load_map(tmp_path / "nested.yaml").occupied.tolist() == [[True, False]]


def test_load_image_threshold_negate_colour_and_16_bit(tmp_path: Path) -> None:
    grey = np.array([[0, 100, 130, 255]], dtype=np.uint8)
    Image.fromarray(grey).save(tmp_path / "g.png")
    assert load_image(tmp_path / "g.png").occupied.tolist() == [[True, True, False, False]]
    assert load_image(tmp_path / "g.png", threshold=0.3).occupied.tolist() == [
        [True, False, False, False]
    ]
    assert load_image(tmp_path / "g.png", negate=True).occupied.tolist() == [
        [False, False, True, True]
    ]
    rgb = np.array([[[255, 0, 0], [255, 255, 0]]], dtype=np.uint8)  # means 85 and 170
    Image.fromarray(rgb).save(tmp_path / "c.bmp")
    assert load_map(tmp_path / "c.bmp").occupied.tolist() == [[True, False]]
    deep = np.array([[1000, 60000]], dtype=np.uint16)
    Image.fromarray(deep).save(tmp_path / "d.png")
    assert load_image(tmp_path / "d.png").occupied.tolist() == [[True, False]]


def test_text_picture_ignores_blank_edges_and_trailing_spaces() -> None:
    g = parse_text_picture("\n\n  \n###  \n#.#\t\n###\n\n", resolution_m=0.5)
    assert g.occupied.tolist() == [[True] * 3, [True, False, True], [True] * 3]
    assert g.extent_m == (-0.75, 0.75, -0.75, 0.75)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.lists(st.booleans(), min_size=3, max_size=3), min_size=1, max_size=6))
def test_text_picture_format_parse_round_trip(rows: list[list[bool]]) -> None:
    g = grid_from_matrix(rows)
    np.testing.assert_array_equal(parse_text_picture(format_text_picture(g)).occupied, g.occupied)


# ------------------------------------------------------------------------------ bad input
def _bad_cases() -> list[tuple[str, str | bytes, tuple[str, ...]]]:
    ros_ok = (
        "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    return [
        ("ragged.txt", "###\n#.\n###\n", ("line 2", "2 cells", "3")),
        ("badchar.txt", "####\n#x.#\n", ("line 2", "column 2", "'x'", "'#'")),
        ("inner_blank.txt", "##\n\n##\n", ("line 2",)),
        ("empty.txt", "\n \n", ("no map lines",)),
        ("two.csv", "1,1\n1,2\n", ("line 2", "field 2", "'2'", "0 or 1")),
        ("ragged.csv", "1,1,1\n1,0\n", ("line 2", "2 fields")),
        ("nores.yaml", ros_ok.replace("resolution: 0.05\n", ""), ("'resolution'", "missing")),
        ("typo.yaml", ros_ok.replace("free_thresh", "free_tresh"), ("'free_thresh'", "free_tresh")),
        ("badres.yaml", ros_ok.replace("0.05", "fine"), ("'resolution'", "'fine'")),
        ("yaw.yaml", ros_ok.replace("[0, 0, 0]", "[0, 0, 0.5]"), ("'origin'", "yaw 0.5")),
        ("noimage.yaml", ros_ok, ("'image'", "m.pgm", "not found")),
        ("broken.yaml", "image: [unclosed\n", ("line", "YAML")),
        ("mode.yaml", ros_ok + "mode: fancy\n", ("'mode'", "'fancy'", "trinary")),
        ("maze.xlsx", "whatever", ("'.xlsx'", ".txt", ".csv", ".png", ".yaml")),
        ("corrupt.png", b"\x89PNG not really", ("corrupt.png",)),
        ("latin1.txt", b"##\n#\xe9\n", ("line 2", "UTF-8")),
    ]


@pytest.mark.parametrize(("name", "content", "expected"), _bad_cases())
def test_bad_map_files_raise_map_format_error(
    tmp_path: Path, name: str, content: str | bytes, expected: tuple[str, ...]
) -> None:
    path = tmp_path / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    with pytest.raises(MapFormatError) as info:
        load_map(path)
    msg = str(info.value)
    assert name in msg
    for part in expected:
        assert part in msg, f"{part!r} not in {msg!r}"


def test_missing_file_names_the_path(tmp_path: Path) -> None:
    with pytest.raises(MapFormatError, match=r"nothere\.txt.*not found"):
        load_map(tmp_path / "nothere.txt")
    with pytest.raises(MapFormatError, match=r"gone\.png"):
        load_image(tmp_path / "gone.png")


@pytest.mark.parametrize(
    ("matrix", "expected"),
    [
        ([[1, 1], [1, 2]], ("inline matrix", "row 2, column 2", "2", "0 or 1")),
        ([[1, 1], [1]], ("inline matrix", "row 2", "1 values")),
        ([], ("inline matrix", "empty")),
        ([[1, "x"]], ("row 1, column 2", "'x'")),
        ([[0.5, 1]], ("row 1, column 1", "0.5")),
    ],
)
def test_bad_matrices(matrix: list, expected: tuple[str, ...]) -> None:
    with pytest.raises(MapFormatError) as info:
        grid_from_matrix(matrix)
    for part in expected:
        assert part in str(info.value)
    assert isinstance(info.value, ValueError)


def test_bad_geometry_arguments_and_ros_resolution_override(tmp_path: Path) -> None:
    with pytest.raises(MapFormatError, match="resolution_m"):
        grid_from_matrix([[1]], resolution_m=-1.0)
    with pytest.raises(MapFormatError, match="origin_xy_m"):
        grid_from_matrix([[1]], origin_xy_m=(0.0, float("nan")))
    yaml_path = save_ros_map(grid_from_matrix(SMALL), tmp_path / "m.yaml")
    with pytest.raises(MapFormatError, match="resolution_m"):
        load_map(yaml_path, resolution_m=0.1)


# ------------------------------------------------------------------------------ maze tools
def test_upsample_keeps_walls_at_random_points() -> None:
    coarse = thesis_maze("thesis_fig16")
    fine = upsample(coarse, 20)
    assert fine.occupied.shape == (400, 400)
    assert fine.resolution_m == 0.05
    assert fine.extent_m == coarse.extent_m
    pts = np.random.default_rng(0).uniform(-10.5, 10.5, size=(20_000, 2))
    np.testing.assert_array_equal(
        fine.is_occupied_at(pts[:, 0], pts[:, 1]), coarse.is_occupied_at(pts[:, 0], pts[:, 1])
    )
    same = upsample(coarse, 1)
    np.testing.assert_array_equal(same.occupied, coarse.occupied)
    assert (same.resolution_m, same.origin_xy_m) == (coarse.resolution_m, coarse.origin_xy_m)
    with pytest.raises(ValueError, match="factor"):
        upsample(coarse, 0)


def test_random_maze_is_deterministic_perfect_and_bordered() -> None:
    rows, cols, c, w = 6, 9, 2, 1
    a = random_maze(rows, cols, 42, corridor_cells=c, wall_cells=w, resolution_m=0.5)
    b = random_maze(
        rows, cols, np.random.default_rng(42), corridor_cells=c, wall_cells=w, resolution_m=0.5
    )
    np.testing.assert_array_equal(a.occupied, b.occupied)
    assert not np.array_equal(a.occupied, random_maze(rows, cols, 43).occupied)
    occ = a.occupied
    assert occ.shape == (rows * (c + w) + w, cols * (c + w) + w) == (19, 28)
    assert occ[0].all() and occ[-1].all() and occ[:, 0].all() and occ[:, -1].all()
    assert a.extent_m == (-7.0, 7.0, -4.75, 4.75)
    assert free_cells_connected(a)
    # a spanning tree of the rooms: rooms * c^2 room cells + (rooms - 1) openings of c * w cells
    rooms = rows * cols
    assert int((~occ).sum()) == rooms * c * c + (rooms - 1) * c * w


def test_random_maze_loops_and_thick_walls() -> None:
    rows, cols, c, w = 4, 5, 3, 2
    full = random_maze(rows, cols, 7, corridor_cells=c, wall_cells=w, loop_fraction=1.0)
    n_walls = rows * (cols - 1) + cols * (rows - 1)
    assert int((~full.occupied).sum()) == rows * cols * c * c + n_walls * c * w
    some = random_maze(rows, cols, 7, corridor_cells=c, wall_cells=w, loop_fraction=0.5)
    tree_free = rows * cols * c * c + (rows * cols - 1) * c * w
    removed = (n_walls - (rows * cols - 1)) // 2  # round(0.5 * 12) = 6
    assert int((~some.occupied).sum()) == tree_free + removed * c * w
    assert free_cells_connected(some) and some.occupied[:w].all()
    with pytest.raises(ValueError, match="loop_fraction"):
        random_maze(2, 2, 0, loop_fraction=1.5)
    with pytest.raises(ValueError, match="rng_or_seed"):
        random_maze(2, 2, None)  # type: ignore[arg-type]


def test_free_cells_connected_uses_4_connectivity() -> None:
    diagonal_only = grid_from_matrix([[1, 1, 1, 1], [1, 0, 1, 1], [1, 1, 0, 1], [1, 1, 1, 1]])
    assert not free_cells_connected(diagonal_only)
    assert free_cells_connected(grid_from_matrix([[0, 0], [1, 0]]))
    assert not free_cells_connected(grid_from_matrix([[1]]))


def test_tile_repeats_east_and_north_centred() -> None:
    g = thesis_maze("thesis_c1")
    t = tile(g, 3, 2)
    assert t.occupied.shape == (40, 60)
    assert t.extent_m == (-30.0, 30.0, -20.0, 20.0)
    for i in range(2):
        for j in range(3):
            np.testing.assert_array_equal(
                t.occupied[20 * i : 20 * i + 20, 20 * j : 20 * j + 20], g.occupied
            )
    # the cell (1, 1) of the south-west copy: x = -30 + 1.5, y = -20 + 18.5
    assert not t.is_occupied_at(-28.5, -1.5) and t.is_occupied_at(-29.5, -1.5)
