"""Schema text and type hashes of the installed message types; the stamp in CDR bytes.

A schema is the full ``ros2msg`` text rosbag2 stores in MCAP (docs/bags.md, "Layout"): the
type's own ``.msg`` file, then for every type it depends on (recursively, depth first, each
once) a line of 80 ``=``, ``MSG: pkg/Type`` and that type's ``.msg`` text, read from the
installed share folders (ament index). :func:`type_hash` is the type's RIHS01 hash, computed
by ``rosbags`` (``Typestore.hash_rihs01``) from that text; it equals the hash rosidl generated
(the installed ``.json`` type description) for every type of the graph.

Why the schema text is not ``rosbags``' ``Typestore.generate_msgdef(type, ros_version=2)``:
that rebuilds the text from the parsed fields -- no comments, no blank lines, one space
between type and name, constants first, ``Header`` spelled ``std_msgs/Header`` -- while
rosbag2 (and so this module) stores the ``.msg`` files verbatim. For each of the 11 graph
types its text is a different byte string (VehicleState: 558 bytes against 2917), so the
schemas of a bag would change; the fields it describes are the same
(``tests/unit/test_bag.py`` checks both).

:func:`cdr_stamp_ns` reads a message's ``header.stamp`` (or a first ``builtin_interfaces/Time``
field, as in ``/clock``) straight from its CDR bytes, without decoding the message.
"""

from __future__ import annotations

import os
import re
import struct
from pathlib import Path

from fourws_common.topics import normalise_type

from .errors import BagError

DELIMITER = "=" * 80

PRIMITIVES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
})
_FIELD_TYPE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_/]*)")


def _share_dir(package: str) -> Path:
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

    try:
        return Path(get_package_share_directory(package))
    except PackageNotFoundError as exc:
        raise BagError(f"interface package '{package}' is not installed (ament index: "
                       f"{os.environ.get('AMENT_PREFIX_PATH', '')!r}); source ros_ws/env.sh"
                       ) from exc


def msg_file(type_name: str) -> Path:
    """The installed ``.msg`` file of ``pkg/msg/Type`` (via the ament index)."""
    pkg, _, name = normalise_type(type_name).split("/")
    path = _share_dir(pkg) / "msg" / f"{name}.msg"
    if not path.is_file():
        raise BagError(f"no message definition {path} for {type_name}")
    return path


def msg_dependencies(text: str, package: str) -> list[str]:
    """Types (``pkg/Type``) used by the fields of a ``.msg`` text, in order of first use.

    Constants and primitives are skipped; a bare ``Type`` means ``package/Type`` (``Header``
    alone means ``std_msgs/Header``, as rosidl reads it).
    """
    deps: list[str] = []
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        m = _FIELD_TYPE.match(stripped)
        if not m:
            continue
        base = m.group(1)
        if base in PRIMITIVES:
            continue
        if "/" in base:
            parts = base.split("/")
            dep = f"{parts[0]}/{parts[-1]}"
        elif base == "Header":
            dep = "std_msgs/Header"
        else:
            dep = f"{package}/{base}"
        if dep not in deps:
            deps.append(dep)
    return deps


def message_definition(type_name: str) -> str:
    """Full ``ros2msg`` schema text of a type, as rosbag2 stores it in MCAP.

    The type's ``.msg`` text, then for each dependency (depth first, each once) a line of
    80 ``=``, ``MSG: pkg/Type`` and the dependency's ``.msg`` text.
    """
    top = normalise_type(type_name)
    top_pkg = top.split("/")[0]
    text = msg_file(top).read_text(encoding="utf-8")
    parts = [text.rstrip("\n")]
    seen: set[str] = set()

    def visit(body: str, pkg: str) -> None:
        for dep in msg_dependencies(body, pkg):
            if dep in seen:
                continue
            seen.add(dep)
            dpkg, dname = dep.split("/")
            dtext = msg_file(f"{dpkg}/msg/{dname}").read_text(encoding="utf-8")
            parts.append(f"{DELIMITER}\nMSG: {dep}\n{dtext.rstrip(chr(10))}")
            visit(dtext, dpkg)

    visit(text, top_pkg)
    return "\n".join(parts) + "\n"


def type_hash(type_name: str, definition: str | None = None) -> str:
    """RIHS01 type hash of ``pkg/msg/Type`` (``""`` if its text cannot be hashed).

    ``rosbags`` parses the schema text (``definition``, by default
    :func:`message_definition`) into an empty type store and hashes the type.
    """
    from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore

    top = normalise_type(type_name)
    text = message_definition(top) if definition is None else definition
    store = get_typestore(Stores.EMPTY)
    try:
        store.register(get_types_from_msg(text, top))
        return store.hash_rihs01(top)
    except (TypesysError, KeyError):
        return ""


def first_field_is_stamp(definition: str) -> bool:
    """True if the message's first field is a ``std_msgs/Header`` or a ``builtin_interfaces/Time``
    (its CDR bytes then start with the stamp: see :func:`cdr_stamp_ns`)."""
    for line in definition.splitlines():
        s = line.strip()
        if s.startswith(DELIMITER):
            return False
        if not s or s.startswith("#"):
            continue
        m = _FIELD_TYPE.match(s)
        if not m or "=" in s.split("#")[0]:
            continue  # a constant is not a field
        return m.group(1) in ("std_msgs/Header", "std_msgs/msg/Header", "Header",
                              "builtin_interfaces/Time", "builtin_interfaces/msg/Time")
    return False


def cdr_stamp_ns(data: bytes | memoryview) -> int | None:
    """Stamp (ns) of a serialized message whose first field is a Header or a Time.

    CDR: 4 bytes of encapsulation (representation 0x0000 big, 0x0001 little endian), then
    ``int32 sec`` and ``uint32 nanosec``. ``None`` if the bytes are too short.
    """
    if len(data) < 12:
        return None
    rep = bytes(data[0:2])
    fmt = "<iI" if rep in (b"\x00\x01", b"\x00\x03") else ">iI"
    sec, nsec = struct.unpack_from(fmt, data, 4)
    return sec * 1_000_000_000 + nsec

