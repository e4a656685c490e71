# SPDX-License-Identifier: GPL-3.0-or-later
"""What DQ Skin reads from a mesh datablock, read once and kept until the mesh changes.

Per mesh (shared by every object using it, e.g. a crowd of linked duplicates): the vertex
positions, the vertex-group weights in stored order, the element counts, and the shape keys'
coordinates. Weights are read straight from Blender's memory through `dqskin.memory.MeshMemory`
(see `memory`), which takes milliseconds where `MeshVertex.groups` takes about a second per
250,000 vertices; if that reader cannot be built, the slow path is used and the panel says
nothing is wrong.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from .. import dqskin


@dataclass
class Groups:
    """Vertex-group weights in CSR form, in stored order (`dqskin.influences_from_deform_groups`)."""

    offsets: np.ndarray
    groups: np.ndarray
    weights: np.ndarray

    def weights_of(self, index: int) -> np.ndarray:
        return dqskin.deform_group_weights(self.offsets, self.groups, self.weights, index)


@dataclass
class KeyData:
    """A mesh's shape keys: their coordinates and how they mix (values come per frame)."""

    relative: bool
    reference: int
    data: list  # (V, 3) float32 per key block, in block order
    relative_to: list  # index of each block's relative key
    vertex_groups: list  # vertex group name per block ("" for none)


def digest_of(groups: Groups | None) -> bytes:
    """What identifies a mesh's weights (compared instead of the arrays once they are released)."""
    h = hashlib.blake2b(digest_size=20)
    if groups is not None:
        for a in (groups.offsets, groups.groups, groups.weights):
            h.update(str(len(a)).encode())
            h.update(np.ascontiguousarray(a).data)
    return h.digest()


@dataclass
class MeshData:
    uid: int
    version: int
    counts: tuple  # vertices, edges, faces, corners
    # What the kernel reads: the mesh's positions where Blender keeps them
    # (`dqskin.memory.MeshPositions`, no copy of ours), or a `(V, 3)` float32 copy where the
    # memory reader cannot give them (edit mode, a Blender it does not know).
    source: object
    held_groups: Groups | None  # the weights as read; None once released or if there are none
    group_names: tuple
    keys: KeyData | None
    has_groups: bool = False  # the mesh has vertex-group data at all
    groups_digest: bytes = b""
    # Reads the weights again from Blender's memory (None: they cannot be read cheaply, so
    # they are kept).
    reload: object = field(default=None, repr=False)
    # The weights read again were not those read first: the mesh is read again on its next use.
    changed_under: bool = False
    positions_digest: bytes = b""
    # A copy of the positions for what needs an array (B-Bone and envelope influences, the
    # Optimized Centers' geometry): read when first needed, dropped by `release_positions`.
    held_positions: np.ndarray | None = field(default=None, repr=False)
    _group_weights: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        if isinstance(self.source, np.ndarray):
            self.held_positions = self.source

    @property
    def vertex_count(self) -> int:
        return self.counts[0]

    @property
    def positions(self) -> np.ndarray:
        """The `(V, 3)` float32 positions as an array (a copy of Blender's, kept until released,
        where the kernel reads them in place)."""
        if self.held_positions is None:
            self.held_positions = self.source.read()
        return self.held_positions

    def release_positions(self) -> None:
        """Drops the copy of the positions where the kernel reads Blender's own."""
        if not isinstance(self.source, np.ndarray):
            self.held_positions = None

    @property
    def groups(self) -> Groups | None:
        """The vertex-group weights (None: the mesh has no vertex-group data at all), read again
        if they were released. Weights changed since (a script painted them and nothing told
        DQ Skin yet) are the ones returned, and the mesh is read again on its next use."""
        if self.held_groups is None and self.has_groups:
            got = self.reload() if self.reload is not None else None
            if got is None or digest_of(got) != self.groups_digest:
                self.changed_under = True
            self.held_groups = got
        return self.held_groups

    def release_groups(self) -> None:
        """Drops the weights once bound (they are read again when needed): a crowd keeps one
        binding per character, not its mesh's weights twice."""
        if self.reload is not None:
            self.held_groups = None

    def group_weights(self, name: str) -> np.ndarray | None:
        """Per-vertex weights of a vertex group by name (None if there is no such group)."""
        if name not in self._group_weights:
            if name not in self.group_names:
                self._group_weights[name] = None
            elif not self.has_groups:
                self._group_weights[name] = np.zeros(self.vertex_count, np.float32)
            else:
                released = self.held_groups is None
                self._group_weights[name] = self.groups.weights_of(self.group_names.index(name))
                if released:
                    self.release_groups()
        return self._group_weights[name]


def read_groups(mesh, reader) -> Groups | None:
    """The mesh's vertex-group weights (None if it has no vertex-group data), from memory with
    `reader` (`dqskin.memory.MeshMemory`, or None for the Python API)."""
    if reader is not None and not mesh.is_editmode:
        try:
            got = reader.deform_verts(mesh)
        except (ValueError, TypeError):
            got = False
        if got is not False:
            return None if got is None else Groups(*got)
    return _read_groups_slowly(mesh)


def _read_groups_slowly(mesh) -> Groups | None:
    # Without the memory reader an empty weight layer cannot be told from none; a mesh whose
    # vertices are in no group counts as having none (only the mask group depends on it).
    if not any(len(v.groups) for v in mesh.vertices):
        return None
    offsets = np.zeros(len(mesh.vertices) + 1, np.uint32)
    groups: list[int] = []
    weights: list[float] = []
    for v in mesh.vertices:
        for g in v.groups:
            groups.append(g.group)
            weights.append(g.weight)
        offsets[v.index + 1] = len(groups)
    return Groups(offsets, np.asarray(groups, np.uint32), np.asarray(weights, np.float32))


def positions_source(mesh, reader):
    """What the kernel reads of the mesh's positions: Blender's own array through a
    `dqskin.memory.MeshPositions` where `reader` can give one, else a copy (`read_positions`)."""
    if reader is not None and not mesh.is_editmode and len(mesh.vertices):
        try:
            got = reader.positions_in_place(mesh)
        except (ValueError, TypeError):
            got = None
        if got is not None:
            return got
    return read_positions(mesh, reader)


def read_positions(mesh, reader) -> np.ndarray:
    """The mesh's `(V, 3)` float32 positions, from memory with `reader` where it can: Blender's
    Python API would make a mesh that shares its positions with its copies (a crowd of
    duplicates) take its own."""
    if reader is not None and not mesh.is_editmode:
        try:
            got = reader.positions(mesh)
        except (ValueError, TypeError):
            got = None
        if got is not None:
            return got
    flat = np.empty(len(mesh.vertices) * 3, np.float32)
    if len(flat):  # an empty mesh has no position attribute at all
        mesh.attributes["position"].data.foreach_get("vector", flat)
    return flat.reshape(-1, 3)


def _keys(mesh) -> KeyData | None:
    key = mesh.shape_keys
    if key is None or not len(key.key_blocks):
        return None
    blocks = list(key.key_blocks)
    data = []
    for kb in blocks:
        flat = np.empty(len(kb.data) * 3, np.float32)
        points = getattr(kb, "points", None)  # the fast path (Blender 4.1+)
        (points if points is not None else kb.data).foreach_get("co", flat)
        data.append(flat.reshape(-1, 3))
    index = {kb.name: i for i, kb in enumerate(blocks)}
    reference = index.get(key.reference_key.name, 0) if key.reference_key is not None else 0
    relative_to = [index.get(kb.relative_key.name, -1) if kb.relative_key is not None else -1 for kb in blocks]
    return KeyData(key.use_relative, reference, data, relative_to, [kb.vertex_group for kb in blocks])


def _reloader(mesh, reader, count: int):
    """Reads `mesh`'s weights again (from memory when it can), or None where reading them again
    would be slow (no memory reader, or the mesh is being edited): then they are kept."""
    if reader is None or mesh.is_editmode:
        return None

    def reload() -> Groups | None:
        try:
            if len(mesh.vertices) != count:
                return None
            return read_groups(mesh, reader)
        except ReferenceError:  # (the mesh is gone: nothing uses these weights any more)
            return None

    return reload


def _read(mesh, uid: int, version: int, group_names: tuple, reader) -> MeshData:
    counts = (len(mesh.vertices), len(mesh.edges), len(mesh.polygons), len(mesh.loops))
    groups = read_groups(mesh, reader)
    source = positions_source(mesh, reader)
    return MeshData(
        uid=uid,
        version=version,
        counts=counts,
        source=source,
        positions_digest=dqskin.memory.positions_digest(source),
        held_groups=groups,
        group_names=group_names,
        keys=_keys(mesh),
        has_groups=groups is not None,
        groups_digest=digest_of(groups),
        reload=_reloader(mesh, reader, counts[0]) if groups is not None else None,
    )


def _kept_source(data: MeshData):
    """The mesh whose positions `data.source` reads in place, or None (it holds an array)."""
    return None if isinstance(data.source, np.ndarray) else data.source.mesh


def _same(a: MeshData, b: MeshData) -> bool:
    if a.counts != b.counts or a.group_names != b.group_names or a.positions_digest != b.positions_digest:
        return False
    if a.has_groups != b.has_groups or a.groups_digest != b.groups_digest:
        return False
    if (a.keys is None) != (b.keys is None):
        return False
    if a.keys is not None:
        ka, kb = a.keys, b.keys
        if (ka.relative, ka.reference, ka.relative_to, ka.vertex_groups) != (kb.relative, kb.reference, kb.relative_to, kb.vertex_groups):
            return False
        if len(ka.data) != len(kb.data) or not all(np.array_equal(x, y) for x, y in zip(ka.data, kb.data)):
            return False
    return True


class MeshCache:
    """What was read of each mesh (by its session uid), kept until Blender says it changed and
    a comparison finds it did (owned by the session). `reader`: the vertex-group memory reader,
    or None (`memory.Readers.mesh`). `interned`: shares the group names of meshes that have the
    same (`model.interned.Interned`)."""

    def __init__(self, interned=None):
        self._interned = interned
        self._cache: dict[int, MeshData] = {}
        self._stale: set[int] = set()
        self._revisions: dict[int, int] = {}  # mesh uid -> how many times Blender said it changed
        self._version = 0

    def forget(self) -> None:
        self._cache.clear()
        self._stale.clear()
        self._revisions.clear()

    def mark_stale(self, mesh_uid: int) -> None:
        """Blender says the mesh may have changed: compare it on its next use."""
        self._stale.add(mesh_uid)
        self._revisions[mesh_uid] = self._revisions.get(mesh_uid, 0) + 1

    def revision(self, mesh) -> int:
        """Changes whenever Blender said the mesh changed, in anything (materials, UV maps,
        colors, normals...), not only in what DQ Skin reads (`MeshData.version`)."""
        return self._revisions.get(mesh.session_uid, 0)

    def nbytes(self) -> int:
        """Bytes of the positions it holds (copies: none where the kernel reads Blender's)."""
        return sum(data.held_positions.nbytes for data in self._cache.values() if data.held_positions is not None)

    def peek(self, obj) -> MeshData | None:
        """The cached data of `obj`'s mesh if it is current (no read)."""
        uid = obj.data.session_uid
        data = None if uid in self._stale else self._cache.get(uid)
        return None if data is None or data.changed_under else data

    def knows_shape_keys_of(self, mesh) -> bool:
        """Whether the cached data of `mesh` (if any) has as many shape keys as the mesh has now
        (none as none): shape keys added or removed by a script are a change of the mesh."""
        data = self._cache.get(mesh.session_uid)
        if data is None:
            return True
        key = mesh.shape_keys
        if key is None:
            return data.keys is None
        return data.keys is not None and len(data.keys.data) == len(key.key_blocks)

    def peek_any(self, obj) -> MeshData | None:
        """The cached data of `obj`'s mesh, current or not (no read)."""
        return self._cache.get(obj.data.session_uid)

    def get(self, obj, reader, verify: bool = False) -> MeshData:
        """The data of `obj`'s mesh, read if unknown, or re-read and compared with `verify`
        (after Blender said the mesh may have changed); the version only changes when
        something did."""
        mesh = obj.data
        uid = mesh.session_uid
        old = self._cache.get(uid)
        if uid in self._stale or (old is not None and old.changed_under):
            self._stale.discard(uid)
            verify = True
        # Vertex group names live on the mesh since Blender 3.0 but Python reaches them through
        # any of its objects. Removing or renaming a group does not always reach the handlers
        # as a change of the mesh: compared on every use (`keys()` reads them all in one C call,
        # cheaper than reading each group's name).
        names = tuple(obj.vertex_groups.keys())
        if old is not None and not verify and names == old.group_names:
            return old
        self._version += 1
        new = _read(mesh, uid, self._version, names if self._interned is None else self._interned(names), reader)
        if old is not None and _same(old, new):
            if _kept_source(old) is not mesh:  # (an array, or a handle of a mesh since replaced)
                old.source, old.held_positions = new.source, new.held_positions
            return old
        self._cache[uid] = new
        return new
