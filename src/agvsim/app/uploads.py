"""What the browser may send: uploads of bounded size, and scenarios that read only the files
sent with them.

"Load scenario" takes a scenario YAML file, or a ``.zip`` holding one scenario and the map
files it names (``world.file``, and the image a ROS map YAML names). Every name in the
scenario must be a plain relative path to a file of the upload: no absolute path, no ``..``,
nothing read from the server's disk. Names are checked against the upload's own list of files
before anything is read, so an error never tells whether some path exists on the server.

Sizes are bounded before anything is parsed: the upload as sent (``max_upload_bytes``), the
number of files in a ``.zip`` and their unpacked total (a zip bomb is refused while it is
read, not after). The scenario itself then goes through the same loader as ``agvsim run``
(its limits on YAML size, aliases, steps, map cells ... apply to the browser too).
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

from agvsim.safe_yaml import YamlInputError, load_yaml

SCENARIO_SUFFIXES = (".yaml", ".yml")
DEFAULT_MAX_UPLOAD_BYTES = 10 * 2**20  # agvsim serve --max-upload-mb


class UploadError(ValueError):
    """An upload refused before it touched the running simulation."""


@dataclass(frozen=True)
class UploadLimits:
    max_upload_bytes: int = DEFAULT_MAX_UPLOAD_BYTES  # one file as sent by the browser
    max_files: int = 64  # in a .zip
    max_unpacked_bytes: int = 4 * DEFAULT_MAX_UPLOAD_BYTES  # all files of a .zip, unpacked

    def check_size(self, name: str, size: int) -> None:
        if size > self.max_upload_bytes:
            raise UploadError(
                f"{name}: {size:,} bytes is more than the {self.max_upload_bytes:,} bytes an "
                "upload may have (agvsim serve --max-upload-mb raises the limit)"
            )


@dataclass(frozen=True)
class Bundle:
    """A scenario and the files uploaded with it (relative POSIX names -> bytes)."""

    scenario: str  # the scenario's name among ``files``
    files: dict[str, bytes] = field(default_factory=dict)

    def write(self, folder: Path) -> Path:
        """Put the files under ``folder`` (a fresh, private folder); the scenario's path."""
        for name, data in self.files.items():
            path = folder / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        return folder / self.scenario


def plain_name(ref: object, where: str) -> str:
    """``ref`` as a relative POSIX path inside an upload; UploadError for anything that could
    reach outside it (absolute, ``..``, a drive, a backslash, an empty or odd name)."""
    allowed = "a relative path inside the upload, like 'map.pgm' or 'maps/floor.yaml'"
    if not isinstance(ref, str) or not ref.strip():
        raise UploadError(f"{where}: {ref!r} is not a file name; give {allowed}")
    if len(ref) > 255 or any(c in ref for c in "\\\0:") or any(ord(c) < 32 for c in ref):
        raise UploadError(f"{where}: {ref[:80]!r} is not allowed; give {allowed}")
    path = PurePosixPath(ref)
    if path.is_absolute() or ref.startswith("~") or ".." in path.parts:
        raise UploadError(f"{where}: {ref!r} is not allowed; give {allowed}")
    return path.as_posix()


def unpack(name: str, content: bytes, limits: UploadLimits) -> Bundle:
    """A browser upload as a :class:`Bundle` (a YAML file alone, or a ``.zip``)."""
    limits.check_size(name, len(content))
    base = PurePosixPath(name.replace("\\", "/")).name or "scenario.yaml"
    suffix = PurePosixPath(base).suffix.lower()
    if suffix in SCENARIO_SUFFIXES:
        return Bundle(base, {base: content})
    if suffix == ".zip":
        return _unzip(base, content, limits)
    raise UploadError(
        f"{base}: load a scenario from a .yaml or .yml file, or from a .zip holding the "
        "scenario and the map files it names"
    )


def _unzip(name: str, content: bytes, limits: UploadLimits) -> Bundle:
    try:
        archive = zipfile.ZipFile(io.BytesIO(content))
        entries = [i for i in archive.infolist() if not i.is_dir()]
    except (zipfile.BadZipFile, ValueError, OSError) as err:
        raise UploadError(f"{name}: not a readable .zip file ({err})") from None
    if len(entries) > limits.max_files:
        raise UploadError(
            f"{name}: {len(entries)} files; a .zip may hold at most {limits.max_files}"
        )
    files: dict[str, bytes] = {}
    budget = limits.max_unpacked_bytes
    for info in entries:
        member = plain_name(info.filename, f"{name}: file {info.filename!r}")
        if member in files:
            raise UploadError(f"{name}: {member!r} is in the archive twice")
        try:
            with archive.open(info) as f:
                data = f.read(budget + 1)  # never more than the budget, whatever it declares
        except (zipfile.BadZipFile, NotImplementedError, RuntimeError, OSError) as err:
            raise UploadError(f"{name}: {member!r} cannot be unpacked ({err})") from None
        budget -= len(data)
        if budget < 0:
            raise UploadError(
                f"{name}: its files unpack to more than {limits.max_unpacked_bytes:,} bytes "
                "(the limit of an upload's unpacked files)"
            )
        files[member] = data
    top = sorted(n for n in files if "/" not in n and n.lower().endswith(SCENARIO_SUFFIXES))
    named = [n for n in top if PurePosixPath(n).stem.lower() == "scenario"]
    if len(top) == 1 or len(named) == 1:
        return Bundle(top[0] if len(top) == 1 else named[0], files)
    found = ", ".join(top) or "none"
    raise UploadError(
        f"{name}: the .zip must hold one scenario YAML at its top level, or name it "
        f"scenario.yaml (YAML files at the top: {found})"
    )


def check_references(world_file: str | None, bundle: Bundle) -> None:
    """Refuse a scenario whose map names a file that is not in ``bundle`` (checked by name
    against the upload's list only, never against the disk)."""
    if world_file is None:
        return
    name = plain_name(world_file, "world.file")
    if name not in bundle.files:
        raise UploadError(_not_sent("world.file", name, bundle))
    if not name.lower().endswith(SCENARIO_SUFFIXES):
        return
    # a ROS map: its YAML names the image, relative to the YAML's folder
    try:  # the scenario loader's bounded reader: an uploaded map YAML may be a bomb too
        doc: Any = load_yaml(bundle.files[name], name)
    except YamlInputError:
        return  # the map loader reports what is wrong with the YAML, naming the line
    image = doc.get("image") if isinstance(doc, dict) else None
    if image is None:
        return  # reported by the map loader (a missing key)
    where = f"{name}: key 'image'"
    rel = plain_name(image, where)
    joined = (PurePosixPath(name).parent / rel).as_posix()
    if ".." in PurePosixPath(joined).parts or joined not in bundle.files:
        raise UploadError(_not_sent(where, joined, bundle))


def _not_sent(where: str, name: str, bundle: Bundle) -> str:
    sent = ", ".join(sorted(bundle.files)) or "none"
    return (
        f"{where}: {name!r} was not uploaded with the scenario (files sent: {sent}). A "
        "scenario from the browser reads only the files sent with it: load a .zip holding "
        "the scenario and its map files"
    )


def refuse_large_uploads(
    server: Any, limits: Callable[[], UploadLimits], notify: Callable[[int, str], None]
) -> bool:
    """Drop a browser upload as it starts when it declares more bytes than the limit: viser
    would otherwise keep all of it in memory before the app sees it (the app's own check then
    refuses it, too late to spare the memory). ``notify(client_id, message)`` tells the
    browser. Uses viser's upload bookkeeping; returns False (and only the later check works)
    where this viser has none."""
    from viser import _messages

    ws = getattr(server, "_websock_server", None)
    transfers = getattr(server.gui, "_current_file_upload_states", None)
    if ws is None or not isinstance(transfers, dict):
        return False

    def on_start(client_id: int, message: Any) -> None:
        limit = limits().max_upload_bytes
        if message.size_bytes > limit:
            transfers.pop(message.transfer_uuid, None)  # its parts are now ignored
            notify(
                client_id,
                f"{message.filename}: {message.size_bytes:,} bytes is more than the "
                f"{limit:,} bytes an upload may have (agvsim serve --max-upload-mb)",
            )

    ws.register_handler(_messages.FileTransferStartUpload, on_start)
    return True
