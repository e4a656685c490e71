"""The routes by which DQ Skin's positions can reach Blender's evaluation, each measurable on
its own copy of a character: the add-on's own (`cache`: a Mesh Cache carrier on the character,
fed inside the first evaluation; `node`: a result object fed likewise and read by the node
group; `result`: the result written after the first evaluation, as before this release, with a
second evaluation each frame) forced per variant; a prototype of the Geometry Nodes file-import
route (Blender 4.5+: the feed writes a PLY file per evaluation, an Import PLY node reads it);
and Blender's floors (what it costs before any skinning)."""

from __future__ import annotations

import os
import struct
import tempfile

import numpy as np

import bpy

from .timing import addon

FOLDER = "/dev/shm" if os.path.isdir("/dev/shm") else tempfile.gettempdir()


class ForcedRoute:
    """While entered, DQ Skin takes route `kind` ("cache", "node", "result") wherever it decides
    (the decision patched; what reaches a modifier from other modifiers still takes the result)."""

    def __init__(self, kind: str):
        self.kind = kind
        self.saved = None

    def enter(self):
        a = addon()
        decisions = a.model.decisions
        RouteKind, Source = a.model.state.RouteKind, a.model.keys.Source
        original = self.saved = decisions.route_for
        kind = RouteKind(self.kind)

        def route_for(source, deform_only, vertices):
            if source is Source.CAPTURE or (deform_only and kind is RouteKind.NODE):
                return original(source, deform_only, vertices)
            return kind

        decisions.route_for = route_for

    def leave(self):
        if self.saved is not None:
            addon().model.decisions.route_for = self.saved
            self.saved = None

    @property
    def hooks(self):
        return (self.enter, self.leave)


def route_of(obj) -> str:
    a = addon()
    mod = a.engine.context.dq_skin_modifiers(obj)[0]
    route = a.SESSION.state_of(obj, mod).output.route
    return route.value if route is not None else ""


# -- the Geometry Nodes file-import route (a prototype, Blender 4.5+) ---------------------------


def has_import_nodes() -> bool:
    return bpy.app.version >= (4, 5, 0)


def _import_group(prefix: str):
    """Geometry Nodes: the PLY file `prefix` + Serial + ".ply" imported, its points' positions
    set on the incoming mesh by index."""
    g = bpy.data.node_groups.new("dqskin bench import", "GeometryNodeTree")
    g.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    g.interface.new_socket("Serial", in_out="INPUT", socket_type="NodeSocketInt")
    g.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    n, link = g.nodes, g.links.new
    gi, go = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
    importer = n.new("GeometryNodeImportPLY")
    number = n.new("FunctionNodeValueToString")
    join = n.new("GeometryNodeStringJoin")
    head, tail = n.new("FunctionNodeInputString"), n.new("FunctionNodeInputString")
    head.string, tail.string = prefix, ".ply"
    link(gi.outputs["Serial"], number.inputs["Value"])
    for s in (tail, number, head):  # a multi-input lists its last link first
        link(s.outputs[0], join.inputs["Strings"])
    link(join.outputs[0], importer.inputs["Path"])
    sample = n.new("GeometryNodeSampleIndex")
    sample.data_type, sample.domain = "FLOAT_VECTOR", "POINT"
    link(importer.outputs[0], sample.inputs["Geometry"])
    link(n.new("GeometryNodeInputPosition").outputs[0], sample.inputs["Value"])
    link(n.new("GeometryNodeInputIndex").outputs[0], sample.inputs["Index"])
    setpos = n.new("GeometryNodeSetPosition")
    link(gi.outputs["Geometry"], setpos.inputs["Geometry"])
    link(sample.outputs[0], setpos.inputs["Position"])
    link(setpos.outputs[0], go.inputs[0])
    return g


class ImportRoute:
    """For live DQ Skin characters `dq` (Linear or Dual Quaternion, bound bones or B-Bones) with
    their rigs: a copy of each mesh whose Geometry Nodes modifier imports a PLY file; one Python
    driver (ordered after every character's bones, as the add-on's feed is) skins them all in one
    call with the characters' own jobs and writes one file each per evaluation, a new name each
    time (the import nodes cache files by name and whole-second modification time) and returns
    the serial the node trees build the names from. What it costs is the route's: the kernel and
    the pose reads are the feed's."""

    def __init__(self, dq, rigs):
        a = addon()
        self.objects, self.members = [], []
        self.serial = 0
        self.carrier = bpy.data.objects.new("dqskin bench import feed", None)
        self.carrier["serial"] = 0
        self.name = f"dqskin_bench_import_{self.carrier.session_uid}"
        driver = self.carrier.driver_add('["serial"]').driver
        driver.type = "SCRIPTED"
        self.variables = 0
        for k, (obj, rig) in enumerate(zip(dq, rigs)):
            mod = a.engine.context.dq_skin_modifiers(obj)[0]
            st = a.SESSION.state_of(obj, mod)
            assert st.status.live and st.output.job is not None, st.status.message
            job = st.output.job
            out = np.empty((len(obj.data.vertices), 3), np.float32)
            own = a.dqskin.SkinJob(
                job.positions,
                job.influences,
                job.deform,
                job.rest,
                method=job.method,
                premat=job.premat,
                postmat=job.postmat,
                mask=job.mask,
                blend=job.blend,
                blend_factor=job.blend_factor,
                centers=job.centers,
                out=out,
            )
            copy = obj.copy()
            copy.data = obj.data.copy()
            copy.name = f"{obj.name} import"
            bpy.context.scene.collection.objects.link(copy)
            for m in list(copy.modifiers):
                copy.modifiers.remove(m)
            prefix = os.path.join(FOLDER, f"dqskin-bench-{os.getpid()}-{copy.session_uid}-")
            m = copy.modifiers.new("Import", "NODES")
            m.node_group = _import_group(prefix)
            socket = next(i.identifier for i in m.node_group.interface.items_tree if getattr(i, "name", "") == "Serial")
            if bpy.app.version >= (5, 2, 0):  # (5.2 moved node group inputs under `properties`)
                path = f'modifiers["Import"].properties.inputs.{socket}.value'
            else:
                path = f'modifiers["Import"]["{socket}"]'
            d = copy.driver_add(path).driver
            d.type = "SCRIPTED"
            v = d.variables.new()
            v.name, v.type = "serial", "SINGLE_PROP"
            v.targets[0].id = self.carrier
            v.targets[0].data_path = '["serial"]'
            d.expression = "serial"
            binding, segments = st.binding.binding, st.binding.segments
            self.variables += a.routes.feed_drivers.order_after_bones(driver, rig, list(binding.bone_names), prefix=f"c{k}_")
            self.members.append((own, rig, binding, segments, st.needs_effective, prefix))
            self.objects.append(copy)
        self.header_of = {}
        namespace = bpy.app.driver_namespace
        pose, rig_module, skin_many, share_from = a.blender.pose, a.blender.rig, a.dqskin.skin_many, a.engine.fed.SHARE_FROM
        readers = a.SESSION.readers

        def skin(*_):
            dg = namespace["depsgraph"]
            reads = pose.PoseReads(readers.pose, readers.pose_error)
            jobs = []
            for job, rig, binding, segments, effective, _ in self.members:
                arm_eval = rig.evaluated_get(dg)
                if effective:
                    job.deform = pose.frame(arm_eval, binding, segments, reads).deform
                else:
                    deform = rig_module.pose_matrices(arm_eval)
                    job.deform = deform if len(deform) == len(binding.bone_indices) else np.ascontiguousarray(deform[binding.bone_indices])
                jobs.append(job)
            skin_many(jobs, share_from=share_from)  # (as the feed's driver)
            self.serial += 1
            for job, *_, prefix in self.members:
                self._write(prefix, self.serial, job.out)
                gone = f"{prefix}{self.serial - 3}.ply"
                if os.path.exists(gone):
                    os.unlink(gone)
            return float(self.serial)

        namespace[self.name] = skin
        driver.expression = f"{self.name}()"

    def _write(self, prefix: str, serial: int, points: np.ndarray) -> None:
        n = len(points)
        header = self.header_of.get(n)
        if header is None:
            header = self.header_of[n] = (
                f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
            ).encode()
        with open(f"{prefix}{serial}.ply", "wb") as f:
            f.write(header)
            f.write(memoryview(np.ascontiguousarray(points, np.float32)).cast("B"))

    def remove(self):
        bpy.app.driver_namespace.pop(self.name, None)
        for o in self.objects:
            group = o.modifiers["Import"].node_group
            bpy.data.objects.remove(o)
            bpy.data.node_groups.remove(group)
        bpy.data.objects.remove(self.carrier)
        for *_, prefix in self.members:
            folder, stem = os.path.split(prefix)
            for f in os.listdir(folder):
                if f.startswith(stem):
                    os.unlink(os.path.join(folder, f))


# -- what Blender costs before any skinning ------------------------------------------------------


class Floors:
    """Each on its own copy of `body` (which carries the Armature modifier on `rig`):
    `floor_mesh_cache`, a Mesh Cache reading a fixed PC2 file with a driver ordered after the
    bound bones that Blender evaluates without Python: the mesh evaluated again after the pose,
    doing nothing; `floor_python_driver`, the same with a Python driver calling a function that
    does nothing (what entering Python from the evaluation costs; `python_calls` counts its
    calls, so that the floor is known to enter Python); `floor_armature_idle`, the
    Armature modifier with vertex groups and envelopes off (Blender's own modifier visiting the
    vertices with no bone to add); `floor_carried`, the Mesh Cache of `floor_mesh_cache` followed
    by DQ Skin's node group on its carried path (what Blender's evaluation costs the chosen route
    for small meshes without any Python: the least a frame of it can cost)."""

    KINDS = ("floor_mesh_cache", "floor_python_driver", "floor_armature_idle", "floor_carried")

    def __init__(self, rig, body, bone_names):
        self.objects = {}
        n = len(body.data.vertices)
        # (Not named like DQ Skin's own files, "dqskin-*.pc2": DQ Skin removes a Mesh Cache reading
        # one of those that no DQ Skin modifier follows, as a copy's leftover carrier.)
        self.path = os.path.join(FOLDER, f"bench-floor-{os.getpid()}-{body.session_uid}.pc2")
        rest = np.empty(n * 3, np.float32)
        body.data.vertices.foreach_get("co", rest)
        with open(self.path, "wb") as f:
            f.write(b"POINTCACHE2\0" + struct.pack("<iiffi", 1, n, 0.0, 1.0, 1) + rest.tobytes())
        self.name = f"dqskin_bench_nothing_{body.session_uid}"
        self.group = None
        self.python_calls = 0
        bpy.app.driver_namespace[self.name] = self._nothing
        for kind in self.KINDS:
            o = body.copy()
            o.data = body.data.copy()
            o.name = f"{body.name} {kind}"
            bpy.context.scene.collection.objects.link(o)
            self.objects[kind] = o
            if kind == "floor_armature_idle":
                arm_mod = next(m for m in o.modifiers if m.type == "ARMATURE")
                arm_mod.use_vertex_groups = arm_mod.use_bone_envelopes = False
                continue
            for m in list(o.modifiers):
                o.modifiers.remove(m)
            m = o.modifiers.new("Floor", "MESH_CACHE")
            m.cache_format, m.filepath = "PC2", self.path
            m.time_mode, m.play_mode, m.eval_frame = "FRAME", "CUSTOM", 0.0
            m.deform_mode, m.interpolation = "OVERWRITE", "NONE"
            driver = m.driver_add("factor").driver
            driver.type = "SCRIPTED"
            addon().routes.feed_drivers.order_after_bones(driver, rig, list(bone_names))
            driver.expression = f"{self.name}()" if kind == "floor_python_driver" else "1.0"
            if kind == "floor_carried":
                a = addon()
                group = o.modifiers.new("DQ Skin floor", "NODES")
                # A copy without DQ Skin's tag: the same nodes, a modifier DQ Skin leaves alone.
                if self.group is None:
                    self.group = a.blender.node_group.ensure_group().copy()
                    del self.group[a.blender.nodes.GROUP_TAG]
                group.node_group = self.group
                a.routes.result_route.set_mode(group, a.model.state.ResultMode.CARRIED)

    def _nothing(self, *_):
        self.python_calls += 1
        return 1.0

    def remove(self):
        bpy.app.driver_namespace.pop(self.name, None)
        for o in self.objects.values():
            bpy.data.objects.remove(o)
        if self.group is not None:
            bpy.data.node_groups.remove(self.group)
        os.unlink(self.path)


class RouteFloor:
    """`floor_route`: DQ Skin's own objects on the route it chose, with no Python of DQ Skin's
    per character and frame (its frame handler only settling the feed's batches, the feed's
    driver calling a function that returns at once): what the route itself costs Blender (the batch's object and Python driver, the
    carriers' drivers, the Mesh Cache or the result object, the node group). `calls` counts the
    driver's calls. The positions stay those of the last full evaluation: timed, not compared."""

    def __init__(self):
        self.calls = 0
        self.saved = None

    def _nothing(self, *_):
        self.calls += 1
        return 1.0

    def enter(self):
        a = addon()
        tracker, feeds = a.engine.tracker.Tracker, a.SESSION.routes.feeds
        self.saved = tracker.frame
        # (Only the feed's bookkeeping: characters just shown leave the batches of their own.)
        tracker.frame = lambda _self, _depsgraph: feeds.commit()
        # (On the instance: the batches' driver looks `run` up on it at each call.)
        feeds.run = self._nothing

    def leave(self):
        if self.saved is None:
            return
        a = addon()
        feeds = a.SESSION.routes.feeds
        a.engine.tracker.Tracker.frame = self.saved
        del feeds.run
        self.saved = None

    @property
    def hooks(self):
        return (self.enter, self.leave)
