"""Acclaim ASF (skeleton) and AMC (joint angles per frame) files: reading, forward kinematics, writing.

Format (Acclaim ASF/AMC as the CMU and HDM05 releases write it): ``#`` starts a comment, commas and parentheses count as
whitespace, keywords start with ``:``. The ASF holds ``:version``, ``:name``,
``:units`` (``mass``, ``length`` multiplier, ``angle deg|rad``), ``:documentation``
(free text up to the next ``:`` keyword), ``:root`` (``order``, ``axis``,
``position``, ``orientation``), ``:bonedata`` (``begin … end`` blocks with ``id``,
``name``, ``direction``, ``length``, ``axis a b c ORDER``, ``dof``, ``limits``) and
``:hierarchy`` (``begin``, ``parent child…`` lines, ``end``). The AMC holds optional
``#`` lines, ``:FULLY-SPECIFIED``, ``:DEGREES``/``:RADIANS``, then per frame a line
with the (1-based) frame number followed by one ``<bone> v1 v2 …`` line per bone
that has degrees of freedom; values follow the bone's ``dof`` order (the root's
follow ``order``). Files are read as Latin-1 (HDM05's headers carry a Latin-1
"ü"); LF and CRLF line ends are both accepted.

Lengths: an ASF ``length`` multiplier ``k`` means one file unit is ``1/k`` inch
(CMU and HDM05 use ``k = 0.45``: one unit = 0.0254/0.45 m ≈ 0.05644 m). Bone
lengths and the root translation in the AMC are in these units;
:attr:`AsfSkeleton.metres_per_unit` converts them (``unit_scale`` overrides it).

Forward kinematics (the convention of the CMU mocap parsers). For every bone
``b`` with parent ``p``::

    C_b = Euler(axis angles, axis order)            # fixed-axis rotations, first letter first
    M_b = Euler(AMC values, dof order)              # rotations of the dofs, in dof order
    L_b = C_b · M_b · C_b⁻¹                         # "local" rotation, stored in Motion.rotations
    R_b = R_p · L_b                                 # global rotation of bone b
    p_b = p_p + R_b · (direction_b · length_b · metres_per_unit)

The root: ``C`` from ``orientation``/``axis``, ``M`` from the rotation channels in
``order``, ``R_root = L_root`` and ``p_root = (position + translation) · metres_per_unit``.
"Euler(angles, order)" composes fixed-axis rotations, the first named axis
applied first: ``order XYZ`` gives ``Rz · Ry · Rx`` (scipy's extrinsic ``"xyz"``).
A joint's position is the END of the bone of that name (CMU ``lfemur`` ends at
the left knee); the root's is the root position. Joint order: root, then the
bones in ASF order, which for CMU and HDM05 files is exactly
:data:`~mocapkit.motion.layouts.CMU31` (``layout_name="cmu31"``).

Raw values. :func:`read_amc` keeps the file's values on the Motion so that
:func:`write_amc` can write them back (read → write → read reproduces positions
to float precision):

- ``metadata["amc_values"]``: ``dict`` bone name → float64 ``[frames, len(dofs)]``,
  the values exactly as in the file (root: one column per ``order`` channel,
  translations in ASF length units; angles in ``metadata["amc_angle_unit"]``);
- ``metadata["amc_angle_unit"]``: ``"deg"`` or ``"rad"``;
- ``metadata["amc_bone_order"]``: the order of the bone lines within a frame (HDM05
  writes the root, the spine, the right arm, ... unlike its ASF order);
- ``metadata["amc_frame_numbers"]``: int64 ``[frames]`` as written;
- ``metadata["amc_header"]``: the header lines before the first frame;
- ``metadata["asf"]``: the :class:`AsfSkeleton` used, ``metadata["asf_path"]`` its path
  (or None).

Unsupported: translation/length dofs (``tx ty tz l``) on non-root bones, which
CMU and HDM05 never use (an :class:`AsfFormatError` names the line).
"""

from __future__ import annotations

import math
import os
import re
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.safe_io import read_file_bytes
from mocapkit.motion.container import Motion
from mocapkit.motion.layouts import CMU31

INCH = 0.0254
DEFAULT_FPS = 120.0
ROTATION_DOFS = ("rx", "ry", "rz")
ROOT_CHANNELS = ("TX", "TY", "TZ", "RX", "RY", "RZ")


class AsfFormatError(MotionFormatError):
    """A malformed ASF file. The message names the file and the 1-based line."""


class AmcFormatError(MotionFormatError):
    """A malformed AMC file (or one that does not fit its ASF). Names the file, 1-based line and frame."""


# --------------------------------------------------------------------------- data


@dataclass
class AsfBone:
    """One ``begin … end`` block of ``:bonedata``.

    Attributes:
        id: the bone's ``id``.
        name: bone name (also the joint name of the bone's end).
        direction: float64 ``[3]`` unit vector in global rest coordinates.
        length: bone length in ASF length units (see :attr:`AsfSkeleton.metres_per_unit`).
        axis: float64 ``[3]`` Euler angles of the bone frame ``C``, in the ASF's angle unit.
        axis_order: rotation order of ``axis``, e.g. ``"XYZ"`` (first letter applied first).
        dof: degrees of freedom in AMC value order, e.g. ``("rx", "ry", "rz")``; empty for fixed bones.
        limits: one ``(min, max)`` pair per dof (``inf`` allowed), in the ASF's angle unit.
        extra: any other ``key values…`` lines of the block (e.g. ``bodymass``), kept as strings.
    """

    id: int
    name: str
    direction: np.ndarray
    length: float
    axis: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis_order: str = "XYZ"
    dof: tuple[str, ...] = ()
    limits: list[tuple[float, float]] = field(default_factory=list)
    extra: dict[str, str] = field(default_factory=dict)


@dataclass
class AsfSkeleton:
    """Everything in an ASF file.

    Attributes:
        name: ``:name``.
        version: ``:version`` (a string, e.g. ``"1.10"``).
        units: ``{"mass": float, "length": float, "angle": "deg" | "rad"}`` plus any other unit entries.
        documentation: the ``:documentation`` text (lines joined with ``\\n``).
        root_order: channel order of the root line in the AMC, e.g. ``("TX","TY","TZ","RX","RY","RZ")``.
        root_axis: rotation order of ``root_orientation``, e.g. ``"XYZ"``.
        root_position: float64 ``[3]`` preset position, ASF length units.
        root_orientation: float64 ``[3]`` preset orientation, ASF angle unit.
        bones: the bones in file order.
        hierarchy: ``parent → children`` in file order (``"root"`` first).
        source: the path read, if any.
    """

    name: str = ""
    version: str = "1.10"
    units: dict = field(default_factory=lambda: {"mass": 1.0, "length": 0.45, "angle": "deg"})
    documentation: str = ""
    root_order: tuple[str, ...] = ROOT_CHANNELS
    root_axis: str = "XYZ"
    root_position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    root_orientation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    bones: list[AsfBone] = field(default_factory=list)
    hierarchy: dict[str, list[str]] = field(default_factory=dict)
    source: str | None = None

    # ---------------------------------------------------------------- derived

    @property
    def bone_names(self) -> tuple[str, ...]:
        return tuple(b.name for b in self.bones)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """``("root", *bone names)``: the joint order of :func:`read_amc`'s Motion."""
        return ("root",) + self.bone_names

    @property
    def parent_names(self) -> dict[str, str]:
        """child → parent from ``hierarchy``."""
        return {c: p for p, children in self.hierarchy.items() for c in children}

    @property
    def parents(self) -> tuple[int, ...]:
        """Parent index per joint in :attr:`joint_names` order (``-1`` for the root)."""
        index = {n: i for i, n in enumerate(self.joint_names)}
        par = self.parent_names
        return (-1,) + tuple(index[par[b.name]] for b in self.bones)

    @property
    def angle_unit(self) -> str:
        return str(self.units.get("angle", "deg")).lower()

    @property
    def length_multiplier(self) -> float:
        return float(self.units.get("length", 1.0))

    @property
    def metres_per_unit(self) -> float:
        """Metres per ASF length unit: ``0.0254 / length`` (one unit = ``1/length`` inch)."""
        return INCH / self.length_multiplier

    @property
    def source_units(self) -> str:
        """A description of the length unit for :attr:`Motion.source_units`, e.g. ``"inch/0.45 (CMU)"``."""
        k = self.length_multiplier
        if math.isclose(k, 0.45):
            return "inch/0.45 (CMU)"
        return f"inch/{k:g}"

    @property
    def layout_name(self) -> str | None:
        """``"cmu31"`` when the joints and hierarchy are exactly CMU31's, else None."""
        if self.joint_names == CMU31.joint_names and self.parents == CMU31.parents:
            return "cmu31"
        return None

    def bone(self, name: str) -> AsfBone:
        for b in self.bones:
            if b.name == name:
                return b
        raise KeyError(f"{self.source or self.name or 'ASF'} has no bone {name!r}")

    def dof_of(self, bone: str) -> tuple[str, ...]:
        """The AMC channels of ``bone`` (the root's are :attr:`root_order`, lower-cased)."""
        if bone == "root":
            return tuple(c.lower() for c in self.root_order)
        return self.bone(bone).dof

    @property
    def amc_bones(self) -> tuple[str, ...]:
        """Bones that appear in an AMC frame: the root, then every bone with a dof, in ASF order."""
        return ("root",) + tuple(b.name for b in self.bones if b.dof)

    def offsets(self, unit_scale: float | None = None) -> np.ndarray:
        """float64 ``[joints, 3]`` rest offsets ``direction · length`` in metres (root row = 0)."""
        scale = self.metres_per_unit if unit_scale is None else unit_scale
        out = np.zeros((len(self.bones) + 1, 3))
        for i, b in enumerate(self.bones):
            out[i + 1] = np.asarray(b.direction, float) * b.length * scale
        return out

    def rest_positions(self, unit_scale: float | None = None) -> np.ndarray:
        """float64 ``[joints, 3]`` metres: the zero pose (every AMC value 0) at the root preset position."""
        values = {bone: np.zeros((1, len(self.dof_of(bone)))) for bone in self.amc_bones}
        return forward_kinematics(self, values, unit_scale=unit_scale, angle_unit=self.angle_unit)[0][0]


# --------------------------------------------------------------------------- ASF reading

_SPLIT = re.compile(r"[\s,()]+")


def _tokens(line: str) -> list[str]:
    line = line.split("#", 1)[0]
    return [t for t in _SPLIT.split(line) if t]


def _read_text(path: Path, error) -> str:
    """The file as text: a regular file of at most ``safe_io.MAX_FILE_BYTES`` (special files are refused)."""
    return read_file_bytes(path, lambda p, message: error(p, None, message)).decode("latin-1")


def read_asf(path: str | os.PathLike) -> AsfSkeleton:
    """Read an ASF skeleton.

    Raises:
        AsfFormatError: unknown section, bad numbers, a dof count that does not match
            the limits, a hierarchy naming an unknown bone, bones outside the hierarchy;
            the message names the file and the 1-based line.
    """
    path = Path(path)
    return parse_asf_text(_read_text(path, AsfFormatError), source=path)


def parse_asf_text(text: str, source: str | os.PathLike = "<memory>") -> AsfSkeleton:
    """Parse the content of an ASF file (see :func:`read_asf`)."""
    lines = text.splitlines()
    skel = AsfSkeleton(units={}, source=str(source))
    section = None
    doc: list[str] = []
    bone: dict | None = None
    bone_line = 0
    last_key = None
    hier_open = False
    hier_lines: dict[str, int] = {}

    def num(tok: str, ln: int, what: str) -> float:
        # NaN is never a value; +-inf only in limits (CMU writes "(-inf inf)" for free dofs);
        # 1e309 overflows to inf and is refused like inf.
        try:
            value = float(tok)
        except ValueError:
            raise AsfFormatError(source, ln, f"non-numeric {what} {tok!r}") from None
        if math.isnan(value) or (math.isinf(value) and what != "limit"):
            raise AsfFormatError(source, ln, f"non-finite {what} {tok!r}")
        return value

    def finish_bone(ln: int) -> None:
        nonlocal bone
        b = bone
        bone = None
        for key in ("name", "direction", "length"):
            if key not in b:
                raise AsfFormatError(source, bone_line, f"bone block has no {key!r}")
        dof = tuple(b.get("dof", ()))
        limits = b.get("limits", [])
        if len(limits) % 2:
            raise AsfFormatError(source, b["limits_line"], "limits need (min max) pairs")
        pairs = [(limits[i], limits[i + 1]) for i in range(0, len(limits), 2)]
        if dof and pairs and len(pairs) != len(dof):
            raise AsfFormatError(
                source, b["limits_line"], f"bone {b['name']}: {len(pairs)} limit pairs for {len(dof)} dofs"
            )
        skel.bones.append(
            AsfBone(
                id=int(b.get("id", len(skel.bones) + 1)),
                name=b["name"],
                direction=b["direction"],
                length=b["length"],
                axis=b.get("axis", np.zeros(3)),
                axis_order=b.get("axis_order", "XYZ"),
                dof=dof,
                limits=pairs,
                extra=b.get("extra", {}),
            )
        )

    for i, raw in enumerate(lines):
        ln = i + 1
        stripped = raw.strip()
        if stripped.startswith(":"):
            if bone is not None:
                raise AsfFormatError(source, ln, f"keyword {stripped.split()[0]} inside a bone block (missing 'end')")
            parts = stripped.split(None, 1)
            section = parts[0][1:].lower()
            rest = parts[1] if len(parts) > 1 else ""
            if section == "version":
                skel.version = rest.split("#")[0].strip()
            elif section == "name":
                skel.name = rest.split("#")[0].strip()
            elif section == "documentation":
                if rest.strip():
                    doc.append(rest.strip())
            elif section in ("units", "root"):
                if rest.strip():  # everything on the keyword line, e.g. ":units mass 1 length 0.45 angle deg"
                    _section_line(skel, section, _tokens(rest), ln, source, num)
            elif section in ("bonedata", "hierarchy", "skin"):  # :skin names skin files: ignored
                pass
            else:
                raise AsfFormatError(source, ln, f"unknown section {parts[0]!r}")
            continue
        if section == "documentation":
            doc.append(raw.rstrip())
            continue
        tok = _tokens(raw)
        if not tok:
            continue
        if section in ("units", "root"):
            _section_line(skel, section, tok, ln, source, num)
        elif section == "bonedata":
            key = tok[0].lower()
            if bone is None:
                if key != "begin":
                    raise AsfFormatError(source, ln, f"expected 'begin' of a bone block, found {tok[0]!r}")
                bone, bone_line, last_key = {}, ln, None
                continue
            if key == "end":
                finish_bone(ln)
                continue
            if key == "begin":
                raise AsfFormatError(source, ln, "'begin' inside a bone block (missing 'end')")
            if last_key == "limits" and _is_number(tok[0]):
                bone["limits"].extend(num(t, ln, "limit") for t in tok)
                continue
            last_key = key
            args = tok[1:]
            if key == "id":
                bone["id"] = int(num(args[0], ln, "id")) if args else 0
            elif key == "name":
                if not args:
                    raise AsfFormatError(source, ln, "bone name is missing")
                bone["name"] = args[0]
            elif key == "direction":
                if len(args) != 3:
                    raise AsfFormatError(source, ln, f"direction needs 3 values, found {len(args)}")
                bone["direction"] = np.array([num(t, ln, "direction") for t in args])
            elif key == "length":
                if len(args) != 1:
                    raise AsfFormatError(source, ln, "length needs 1 value")
                bone["length"] = num(args[0], ln, "length")
            elif key == "axis":
                if len(args) != 4:
                    raise AsfFormatError(source, ln, f"axis needs 3 angles and an order, found {args}")
                bone["axis"] = np.array([num(t, ln, "axis angle") for t in args[:3]])
                bone["axis_order"] = _check_order(args[3], ln, source)
            elif key == "dof":
                dof = tuple(t.lower() for t in args)
                bad = [d for d in dof if d not in ROTATION_DOFS]
                if bad:
                    raise AsfFormatError(source, ln, f"unsupported dof {bad[0]!r} (only rx, ry, rz are supported)")
                bone["dof"] = dof
            elif key == "limits":
                bone["limits"] = [num(t, ln, "limit") for t in args]
                bone["limits_line"] = ln
            else:
                bone.setdefault("extra", {})[key] = " ".join(args)
        elif section == "hierarchy":
            key = tok[0].lower()
            if key == "begin":
                hier_open = True
                continue
            if key == "end":
                hier_open = False
                continue
            if not hier_open:
                raise AsfFormatError(source, ln, f"hierarchy line outside begin/end: {raw.strip()!r}")
            skel.hierarchy.setdefault(tok[0], []).extend(tok[1:])
            hier_lines[tok[0]] = ln
        elif section is None:
            raise AsfFormatError(source, ln, f"content before the first keyword: {raw.strip()[:40]!r}")
        else:  # version/name continuation lines are not expected
            raise AsfFormatError(source, ln, f"unexpected line in :{section}: {raw.strip()[:40]!r}")
    if bone is not None:
        raise AsfFormatError(source, len(lines), "file ends inside a bone block")
    skel.documentation = textwrap.dedent("\n".join(doc)).strip("\n")
    skel.units.setdefault("mass", 1.0)
    skel.units.setdefault("length", 1.0)
    skel.units.setdefault("angle", "deg")
    if skel.units["angle"] not in ("deg", "rad"):
        raise AsfFormatError(source, None, f"angle unit must be deg or rad, got {skel.units['angle']!r}")
    _check_hierarchy(skel, hier_lines, source)
    return skel


def _is_number(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def _check_order(order: str, ln: int, source) -> str:
    order = order.upper()
    if len(order) != 3 or set(order) != set("XYZ"):
        raise AsfFormatError(source, ln, f"rotation order must be a permutation of XYZ, got {order!r}")
    return order


def _section_line(skel: AsfSkeleton, section: str, tok: list[str], ln: int, source, num) -> None:
    if section == "units":
        if len(tok) % 2:
            raise AsfFormatError(source, ln, f"units need 'name value' pairs, found {tok}")
        for key, value in zip(tok[::2], tok[1::2]):
            key = key.lower()
            skel.units[key] = value.lower() if key == "angle" else num(value, ln, f"{key} unit")
            if key == "length" and not skel.units[key] > 0:
                raise AsfFormatError(source, ln, f"length unit must be positive, got {value}")
        return
    key, args = tok[0].lower(), tok[1:]
    if key == "order":
        channels = tuple(a.upper() for a in args)
        bad = [c for c in channels if c not in ROOT_CHANNELS]
        if bad or len(set(channels)) != len(channels):
            raise AsfFormatError(source, ln, f"root order must be distinct channels of {ROOT_CHANNELS}, got {args}")
        skel.root_order = channels
    elif key == "axis":
        if len(args) != 1:
            raise AsfFormatError(source, ln, "root axis needs one rotation order")
        skel.root_axis = _check_order(args[0], ln, source)
    elif key in ("position", "orientation"):
        if len(args) != 3:
            raise AsfFormatError(source, ln, f"root {key} needs 3 values, found {len(args)}")
        setattr(skel, f"root_{key}", np.array([num(t, ln, f"root {key}") for t in args]))
    else:
        raise AsfFormatError(source, ln, f"unknown root field {tok[0]!r}")


def _check_hierarchy(skel: AsfSkeleton, hier_lines: dict[str, int], source) -> None:
    names = set(skel.bone_names)
    if len(names) != len(skel.bones):
        dup = next(n for n in skel.bone_names if skel.bone_names.count(n) > 1)
        raise AsfFormatError(source, None, f"bone {dup!r} is defined twice")
    if "root" in names:
        raise AsfFormatError(source, None, "a bone may not be called 'root'")
    seen_children: set[str] = set()
    for parent, children in skel.hierarchy.items():
        if parent != "root" and parent not in names:
            raise AsfFormatError(source, hier_lines.get(parent), f"hierarchy names unknown bone {parent!r}")
        for c in children:
            if c not in names:
                raise AsfFormatError(source, hier_lines.get(parent), f"hierarchy names unknown bone {c!r}")
            if c in seen_children:
                raise AsfFormatError(source, hier_lines.get(parent), f"bone {c!r} has two parents")
            seen_children.add(c)
    orphans = [n for n in skel.bone_names if n not in seen_children]
    if orphans:
        raise AsfFormatError(source, None, f"bones not in the hierarchy: {orphans}")
    # every bone must reach the root (no cycles)
    par = skel.parent_names
    for n in skel.bone_names:
        seen, cur = set(), n
        while cur != "root":
            if cur in seen:
                raise AsfFormatError(source, hier_lines.get(cur), f"hierarchy has a cycle through {cur!r}")
            seen.add(cur)
            cur = par[cur]


# --------------------------------------------------------------------------- ASF writing


def write_asf(path: str | os.PathLike, skel: AsfSkeleton, newline: str = "\n") -> None:
    """Write ``skel`` as an ASF file that :func:`read_asf` reads back equal (numbers printed with 10 digits)."""
    g = _fmt
    out = ["# ASF file written by mocapkit", f":version {skel.version}", f":name {skel.name}", ":units"]
    for key, value in skel.units.items():
        out.append(f"  {key} {value if isinstance(value, str) else g(value)}")
    if skel.documentation:
        out.append(":documentation")
        out.extend(f"  {ln}" if ln else "" for ln in skel.documentation.split("\n"))
    out += [
        ":root",
        "   order " + " ".join(skel.root_order),
        f"   axis {skel.root_axis}",
        "   position " + " ".join(g(v) for v in skel.root_position),
        "   orientation " + " ".join(g(v) for v in skel.root_orientation),
        ":bonedata",
    ]
    for b in skel.bones:
        out += [
            "  begin",
            f"     id {b.id}",
            f"     name {b.name}",
            "     direction " + " ".join(g(v) for v in b.direction),
            f"     length {g(b.length)}",
            "     axis " + " ".join(g(v) for v in b.axis) + f"  {b.axis_order}",
        ]
        if b.dof:
            out.append("    dof " + " ".join(b.dof))
            if b.limits:
                for k, (lo, hi) in enumerate(b.limits):
                    out.append(("    limits " if k == 0 else "           ") + f"({g(lo)} {g(hi)})")
        for key, value in b.extra.items():
            out.append(f"     {key} {value}")
        out.append("  end")
    out += [":hierarchy", "  begin"]
    for parent, children in skel.hierarchy.items():
        out.append(f"    {parent} " + " ".join(children))
    out.append("  end")
    Path(path).write_text(newline.join(out) + newline, encoding="latin-1", newline="")


def _fmt(v: float) -> str:
    v = float(v)
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.10g}"


# --------------------------------------------------------------------------- forward kinematics


def _euler(order: str, angles: np.ndarray) -> np.ndarray:
    """Fixed-axis rotation matrices ``[..., 3, 3]``: angles (radians) ``[..., len(order)]``, first axis applied first."""
    angles = np.asarray(angles, dtype=np.float64)
    lead = angles.shape[:-1]
    if not order:
        return np.broadcast_to(np.eye(3), lead + (3, 3)).copy()
    mats = Rotation.from_euler(order.lower(), angles.reshape(-1, len(order))).as_matrix()
    return mats.reshape(lead + (3, 3))


def _bone_frame(angles: np.ndarray, order: str, angle_unit: str) -> np.ndarray:
    a = np.asarray(angles, float)
    if angle_unit == "deg":
        a = np.deg2rad(a)
    return _euler(order, a)


def _topological(parents: tuple[int, ...]) -> list[int]:
    order, frontier = [], [j for j, p in enumerate(parents) if p < 0]
    children: dict[int, list[int]] = {}
    for j, p in enumerate(parents):
        children.setdefault(p, []).append(j)
    while frontier:
        j = frontier.pop(0)
        order.append(j)
        frontier.extend(children.get(j, []))
    return order


def forward_kinematics(
    skel: AsfSkeleton, values: dict[str, np.ndarray], unit_scale: float | None = None, angle_unit: str = "deg"
) -> tuple[np.ndarray, np.ndarray]:
    """Joint positions and local rotations from per-bone AMC values (module docstring for the convention).

    Args:
        skel: the skeleton.
        values: bone name → ``[frames, len(dof)]`` AMC values (root: one column per
            :attr:`AsfSkeleton.root_order` channel, translation in ASF length units).
            Bones with dofs that are absent from ``values`` stay at 0.
        unit_scale: metres per ASF length unit (default :attr:`AsfSkeleton.metres_per_unit`).
        angle_unit: ``"deg"`` or ``"rad"``, the unit of the angles in ``values``.

    Returns:
        ``(positions, rotations)``: float64 ``[frames, joints, 3]`` metres and float64
        ``[frames, joints, 3, 3]`` local rotations ``L``, joints in :attr:`AsfSkeleton.joint_names` order.
    """
    scale = skel.metres_per_unit if unit_scale is None else float(unit_scale)
    lengths = {len(np.asarray(v).reshape(len(v), -1)) for v in values.values()}
    if len(lengths) > 1:
        raise ValueError(f"all bones need the same number of frames, got {sorted(lengths)}")
    T = lengths.pop() if lengths else 1
    names = skel.joint_names
    parents = skel.parents
    J = len(names)
    local = np.empty((T, J, 3, 3))
    positions = np.empty((T, J, 3))
    glob = np.empty((T, J, 3, 3))

    # root
    order = skel.root_order
    root = np.asarray(values.get("root", np.zeros((T, len(order)))), float).reshape(T, len(order))
    trans = np.tile(np.asarray(skel.root_position, float), (T, 1))
    rot_cols, rot_axes = [], ""
    for k, ch in enumerate(order):
        if ch[0] == "T":
            trans[:, "XYZ".index(ch[1])] += root[:, k]
        else:
            rot_cols.append(k)
            rot_axes += ch[1]
    M = _bone_frame(root[:, rot_cols], rot_axes, angle_unit)
    C = _bone_frame(skel.root_orientation, skel.root_axis, skel.angle_unit)
    local[:, 0] = C @ M @ C.T
    glob[:, 0] = local[:, 0]
    positions[:, 0] = trans * scale

    offsets = skel.offsets(scale)
    for j in _topological(parents):
        if j == 0:
            continue
        b = skel.bones[j - 1]
        C = _bone_frame(b.axis, b.axis_order, skel.angle_unit)
        if b.dof:
            v = np.asarray(values.get(b.name, np.zeros((T, len(b.dof)))), float).reshape(T, len(b.dof))
            M = _bone_frame(v, "".join(d[1] for d in b.dof), angle_unit)
            local[:, j] = C @ M @ C.T
        else:
            local[:, j] = np.eye(3)
        p = parents[j]
        glob[:, j] = glob[:, p] @ local[:, j]
        positions[:, j] = positions[:, p] + glob[:, j] @ offsets[j]
    return positions, local


# --------------------------------------------------------------------------- AMC reading


def find_asf(amc_path: str | os.PathLike) -> Path:
    """The ASF that belongs to ``amc_path``, looked up beside it.

    In order: the ``.asf`` with the same stem (``test.amc`` → ``test.asf``); the
    ``.asf`` whose stem is the longest prefix of the AMC stem (CMU ``01_01.amc`` →
    ``01.asf``, HDM05 ``HDM_dg_06-03_03_120.amc`` → ``HDM_dg.asf``, ``charleston1.amc`` →
    ``charleston.asf``); the ``.asf`` whose stem, without an ``HDM_`` prefix, is one of
    the ``_``-separated parts of the AMC stem (``walk2StepsLstart_bd_001.amc`` →
    ``HDM_bd.asf``); the only ``.asf`` in the folder.

    Raises:
        FileNotFoundError: no ``.asf`` in the folder.
        ValueError: several candidates and none of the rules picks one.
    """
    amc_path = Path(amc_path)
    folder = amc_path.parent
    stem = amc_path.stem
    candidates = (
        sorted(p for p in folder.iterdir() if p.suffix.lower() == ".asf" and p.is_file()) if folder.is_dir() else []
    )
    if not candidates:
        raise FileNotFoundError(f"{amc_path}: no .asf skeleton beside it in {folder}; pass asf= explicitly")
    for p in candidates:
        if p.stem == stem:
            return p
    prefixed = [p for p in candidates if stem.startswith(p.stem)]
    if prefixed:
        return max(prefixed, key=lambda p: len(p.stem))
    parts = set(stem.split("_"))
    named = [p for p in candidates if (p.stem.removeprefix("HDM_")) in parts]
    if len(named) == 1:
        return named[0]
    if len(candidates) == 1:
        return candidates[0]
    raise ValueError(
        f"{amc_path}: cannot tell which skeleton it uses among {[p.name for p in candidates]}; pass asf= explicitly"
    )


def read_amc(
    path: str | os.PathLike,
    asf: AsfSkeleton | str | os.PathLike | None = None,
    fps: float = DEFAULT_FPS,
    unit_scale: float | None = None,
) -> Motion:
    """Read an AMC motion and run forward kinematics over its ASF skeleton.

    Args:
        path: the ``.amc`` file.
        asf: an :class:`AsfSkeleton`, a path to the ``.asf``, or None to find it beside the
            AMC (:func:`find_asf`).
        fps: frame rate (AMC files do not store it; CMU and HDM05 capture at 120 Hz).
        unit_scale: metres per ASF length unit (default :attr:`AsfSkeleton.metres_per_unit`).

    Returns:
        A :class:`Motion`: positions float32 ``[frames, joints, 3]`` metres (y up),
        joints = root then the ASF bones in ASF order (``layout_name="cmu31"`` for
        CMU/HDM05 skeletons), ``rotations`` the local ``L`` of each joint, raw values in
        ``metadata`` (see the module docstring).

    Raises:
        AmcFormatError: truncated frames, unknown or repeated bones, non-numeric values,
            wrong value counts; the message names the file, line and frame.
        FileNotFoundError / ValueError: the ASF cannot be found (see :func:`find_asf`).
    """
    path = Path(path)
    asf_path = None
    if asf is None:
        asf_path = find_asf(path)
        skel = read_asf(asf_path)
    elif isinstance(asf, AsfSkeleton):
        skel = asf
        asf_path = Path(asf.source) if asf.source and os.path.exists(asf.source) else None
    else:
        asf_path = Path(asf)
        skel = read_asf(asf_path)
    text = _read_text(path, AmcFormatError)
    parsed = parse_amc_text(text, skel, source=path)
    return amc_motion(
        skel,
        parsed["values"],
        fps=fps,
        unit_scale=unit_scale,
        angle_unit=parsed["angle_unit"],
        name=path.stem,
        source=str(path),
        metadata={
            "amc_bone_order": parsed["bone_order"],
            "amc_frame_numbers": parsed["frame_numbers"],
            "amc_header": parsed["header"],
            "asf_path": None if asf_path is None else str(asf_path),
        },
    )


def amc_motion(
    skel: AsfSkeleton,
    values: dict[str, np.ndarray],
    fps: float = DEFAULT_FPS,
    unit_scale: float | None = None,
    angle_unit: str = "deg",
    name: str = "",
    source: str | None = None,
    metadata: dict | None = None,
) -> Motion:
    """A :class:`Motion` from per-bone AMC values (what :func:`read_amc` returns, without a file)."""
    positions, local = forward_kinematics(skel, values, unit_scale=unit_scale, angle_unit=angle_unit)
    meta = {
        "amc_values": {k: np.asarray(v, dtype=np.float64) for k, v in values.items()},
        "amc_angle_unit": angle_unit,
        "amc_bone_order": tuple(skel.amc_bones),
        "asf": skel,
    }
    meta.update(metadata or {})
    scale = skel.metres_per_unit if unit_scale is None else unit_scale
    units = skel.source_units if unit_scale is None else f"{scale:g} m per unit"
    return Motion(
        positions=positions.astype(np.float32),
        joint_names=skel.joint_names,
        parents=skel.parents,
        fps=fps,
        rotations=local.astype(np.float32),
        source_units=units,
        up_axis="y",
        name=name,
        source=source,
        layout_name=skel.layout_name,
        metadata=meta,
    )


def parse_amc_text(text: str, skel: AsfSkeleton, source: str | os.PathLike = "<memory>") -> dict:
    """Parse the content of an AMC file against ``skel``.

    Returns:
        ``{"values": {bone: float64 [frames, dofs]}, "angle_unit": "deg"|"rad",
        "bone_order": tuple, "frame_numbers": int64 [frames], "header": list[str]}``.
    """
    lines = text.splitlines()
    angle_unit = skel.angle_unit
    header: list[str] = []
    i, n = 0, len(lines)
    # header: comments and keywords up to the first frame number
    while i < n:
        s = lines[i].strip()
        if not s or s.startswith("#"):
            header.append(lines[i])
            i += 1
            continue
        if s.startswith(":"):
            header.append(lines[i])
            kw = s.split()[0].upper()
            if kw == ":DEGREES":
                angle_unit = "deg"
            elif kw == ":RADIANS":
                angle_unit = "rad"
            i += 1
            continue
        break
    if i >= n:
        raise AmcFormatError(source, n + 1 if n else 1, "no frames: expected a frame number after the header")

    expected = skel.amc_bones
    ndof = {b: len(skel.dof_of(b)) for b in expected}
    all_bones = set(skel.joint_names)
    nexp = len(expected)
    # Walk the lines once: frame-number lines and bone lines.
    frame_numbers: list[int] = []
    rows: dict[str, list[str]] = {b: [] for b in expected}
    row_lines: dict[str, list[int]] = {b: [] for b in expected}
    bone_order: list[str] | None = None
    current: list[str] = []
    frame_line = 0

    def close_frame(at_line: int) -> None:
        nonlocal bone_order
        if len(current) != nexp:
            missing = [b for b in expected if b not in current]
            raise AmcFormatError(
                source,
                at_line,
                f"frame {frame_numbers[-1]} (started at line {frame_line}) is truncated: "
                f"{len(current)} of {nexp} bone lines, missing {missing[:4]}"
                f"{' ...' if len(missing) > 4 else ''}",
                frame=len(frame_numbers),
            )
        if bone_order is None:
            bone_order = list(current)

    while i < n:
        raw = lines[i]
        ln = i + 1
        i += 1
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split(None, 1)
        first = parts[0]
        rest = parts[1] if len(parts) > 1 else ""
        if first.isdigit() or (first[0] in "+-" and first[1:].isdigit()):
            if not rest:
                if frame_numbers:
                    close_frame(ln)
                if len(first.lstrip("+-")) > 18:  # beyond int64: no real frame number
                    raise AmcFormatError(
                        source, ln, f"frame number {first[:24]}... is out of range", frame=len(frame_numbers) + 1
                    )
                frame_numbers.append(int(first))
                current = []
                frame_line = ln
                continue
        if not frame_numbers:
            raise AmcFormatError(source, ln, f"expected a frame number, found {s[:40]!r}")
        name = first
        if name not in ndof:
            if name in all_bones:
                raise AmcFormatError(
                    source, ln, f"bone {name!r} has no dof in the ASF but has a line here", frame=len(frame_numbers)
                )
            if _is_number(name):
                raise AmcFormatError(
                    source, ln, f"expected a bone line or a frame number, found {s[:40]!r}", frame=len(frame_numbers)
                )
            raise AmcFormatError(
                source, ln, f"unknown bone {name!r} (not in {skel.source or 'the ASF'})", frame=len(frame_numbers)
            )
        if name in current:
            raise AmcFormatError(
                source, ln, f"bone {name!r} appears twice in frame {frame_numbers[-1]}", frame=len(frame_numbers)
            )
        current.append(name)
        rows[name].append(rest)
        row_lines[name].append(ln)
    close_frame(n + 1)

    T = len(frame_numbers)
    values: dict[str, np.ndarray] = {}
    for b in expected:
        k = ndof[b]
        joined = " ".join(rows[b]).split()
        arr = None
        if len(joined) == T * k:
            try:
                arr = np.array(joined, dtype=np.float64).reshape(T, k)
            except ValueError:
                arr = None
        if arr is None:  # find the offending line
            for t, (r, ln) in enumerate(zip(rows[b], row_lines[b])):
                tok = r.split()
                if len(tok) != k:
                    raise AmcFormatError(
                        source,
                        ln,
                        f"bone {b!r} needs {k} values ({' '.join(skel.dof_of(b))}), found {len(tok)}",
                        frame=t + 1,
                    )
                for v in tok:
                    try:
                        float(v)
                    except ValueError:
                        raise AmcFormatError(
                            source, ln, f"non-numeric value {v!r} for bone {b!r}", frame=t + 1
                        ) from None
            raise AmcFormatError(source, None, f"unparseable values for bone {b!r}")  # pragma: no cover
        if not np.isfinite(arr).all():
            t = int(np.argwhere(~np.isfinite(arr).all(axis=1))[0, 0])
            raise AmcFormatError(source, row_lines[b][t], f"non-finite value for bone {b!r}", frame=t + 1)
        values[b] = arr
    return {
        "values": values,
        "angle_unit": angle_unit,
        "bone_order": tuple(bone_order or expected),
        "frame_numbers": np.asarray(frame_numbers, dtype=np.int64),
        "header": header,
    }


# --------------------------------------------------------------------------- AMC writing


def write_amc(
    path: str | os.PathLike,
    motion_or_angles: Motion | dict[str, np.ndarray],
    asf: AsfSkeleton | str | os.PathLike | None = None,
    angle_unit: str | None = None,
    newline: str = "\n",
    digits: int = 10,
) -> None:
    """Write an AMC file.

    Args:
        motion_or_angles: a Motion from :func:`read_amc` / :func:`amc_motion` (its
            ``metadata["amc_values"]`` is written), or a dict bone → ``[frames, dofs]`` values
            (root: one column per ``root_order`` channel, translation in ASF units).
        asf: the skeleton (an :class:`AsfSkeleton` or a path); optional for a Motion that
            carries ``metadata["asf"]``.
        angle_unit: unit of the angles given, ``"deg"`` (default for a dict) or ``"rad"``;
            for a Motion, its ``metadata["amc_angle_unit"]``. The file's header says which.
        digits: significant digits of the values (default 10: read → write → read reproduces
            positions to far better than 1e-6 m; the synthetic generator uses 6).

    Bone lines follow ``metadata["amc_bone_order"]``
    if present, else :attr:`AsfSkeleton.amc_bones`; frames are numbered 1..T (or
    ``metadata["amc_frame_numbers"]``).
    """
    frame_numbers = None
    order = None
    header_comment = None
    if isinstance(motion_or_angles, Motion):
        meta = motion_or_angles.metadata
        if "amc_values" not in meta:
            raise ValueError(
                f"{motion_or_angles.source or motion_or_angles.name}: the Motion has no "
                f"metadata['amc_values'] (only motions read from AMC or built by amc_motion have them)"
            )
        values = meta["amc_values"]
        angle_unit = angle_unit or meta.get("amc_angle_unit", "deg")
        order = meta.get("amc_bone_order")
        frame_numbers = meta.get("amc_frame_numbers")
        if asf is None:
            asf = meta.get("asf")
    else:
        values = motion_or_angles
        angle_unit = angle_unit or "deg"
    if asf is None:
        raise ValueError("write_amc needs the ASF skeleton (asf=)")
    skel = asf if isinstance(asf, AsfSkeleton) else read_asf(asf)
    if angle_unit not in ("deg", "rad"):
        raise ValueError(f"angle_unit must be 'deg' or 'rad', got {angle_unit!r}")
    expected = skel.amc_bones
    order = tuple(order) if order is not None and set(order) == set(expected) else expected
    unknown = sorted(set(values) - set(skel.joint_names))
    if unknown:
        raise ValueError(f"values for bones not in the skeleton: {unknown}")
    T = None
    arrays = {}
    for b in order:
        k = len(skel.dof_of(b))
        if b not in values:
            raise ValueError(f"no values for bone {b!r} ({k} dofs)")
        a = np.asarray(values[b], dtype=np.float64)
        a = a.reshape(len(a), -1) if a.ndim else a.reshape(1, 1)
        if a.shape[1] != k:
            raise ValueError(f"bone {b!r} needs {k} values per frame, got {a.shape[1]}")
        if T is None:
            T = len(a)
        elif len(a) != T:
            raise ValueError(f"bone {b!r} has {len(a)} frames, expected {T}")
        if not np.isfinite(a).all():
            raise ValueError(f"bone {b!r} has non-finite values")
        arrays[b] = a
    T = T or 0
    if frame_numbers is None or len(frame_numbers) != T:
        frame_numbers = np.arange(1, T + 1)
    fmt = {b: b + "".join(f" %.{int(digits)}g" for _ in range(arrays[b].shape[1])) for b in order}
    text_rows = {b: [fmt[b] % tuple(r) for r in arrays[b].tolist()] for b in order}
    header_comment = f"#!OML:ASF {skel.source}" if skel.source else "# AMC file written by mocapkit"
    out = [header_comment, ":FULLY-SPECIFIED", ":DEGREES" if angle_unit == "deg" else ":RADIANS"]
    for t in range(T):
        out.append(str(int(frame_numbers[t])))
        out.extend(text_rows[b][t] for b in order)
    Path(path).write_text(newline.join(out) + newline, encoding="latin-1", newline="")
