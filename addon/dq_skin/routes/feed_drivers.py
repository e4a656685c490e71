# SPDX-License-Identifier: GPL-3.0-or-later
"""The drivers around the feed (`routes.feed`): the variables that make Blender run a batch's
driver after every input of its members, and so whenever one of them changes (its bones, its
objects' transforms, its shape keys), and the carriers' drivers that read the batch's
property, which orders each carrier after its batch."""

from __future__ import annotations

PROPERTY = "dq_skin_go"
PATH = f'["{PROPERTY}"]'


def drive_carrier(owner, carrier, prop: str, expression: str, feed) -> None:
    """`carrier.prop` on `owner` driven by the feed's property through `expression` (a value that
    leaves the carrier as it is): the driver orders the carrier after the feed."""
    path = f'modifiers["{carrier.name}"].{prop}'
    fc = owner.animation_data.drivers.find(path) if owner.animation_data else None
    if fc is None:
        fc = carrier.driver_add(prop)
        driver = fc.driver
        driver.type = "SCRIPTED"
        v = driver.variables.new()
        v.name, v.type = "go", "SINGLE_PROP"
        driver.expression = expression
    v = fc.driver.variables[0]
    if v.targets[0].id != feed:
        v.targets[0].id = feed
        v.targets[0].data_path = PATH


def order_after_inputs(driver, members) -> int:
    """Variables that make Blender evaluate `driver` after every input of `members`: their
    armatures' bound bones (`order_after_bones`), their objects' and armatures' transforms, and
    their shape keys. Returns how many."""
    bones: dict[int, tuple] = {}
    moved, keys = {}, {}
    for m in members:
        arm = m.armature
        have = bones.get(arm.session_uid, (arm, ()))[1]
        bones[arm.session_uid] = (arm, tuple(dict.fromkeys(have + tuple(m.bones))))
        moved.setdefault(m.target.obj.session_uid, m.target.obj)
        moved.setdefault(arm.session_uid, arm)
        if m.shape_keys is not None:
            keys.setdefault(m.shape_keys.session_uid, m.shape_keys)
    count = 0
    for k, (arm, names) in enumerate(bones.values()):
        count += order_after_bones(driver, arm, names, prefix=f"b{k}_")
    for k, obj in enumerate(moved.values()):
        v = driver.variables.new()
        v.name, v.type = f"t{k}", "TRANSFORMS"
        v.targets[0].id = obj
        v.targets[0].transform_type, v.targets[0].transform_space = "LOC_X", "WORLD_SPACE"
        count += 1
    for k, key in enumerate(keys.values()):
        v = driver.variables.new()
        v.name, v.type = f"k{k}", "SINGLE_PROP"
        v.targets[0].id_type = "KEY"
        v.targets[0].id = key
        # (The Key's own property: Blender runs the driver when any shape key's value changes,
        # keyed, driven or set; `key_blocks[0].value` follows the first shape key alone.)
        v.targets[0].data_path = "eval_time"
        count += 1
    return count


def order_after_bones(driver, armature, names, prefix: str = "b") -> int:
    """Adds the variables that make Blender evaluate `driver` after every bone of `names`: each
    B-Bone's segments (a B-Bone property links to them), and the bones with no bound descendant
    (a bone is done after its parent, so after those every bound bone is); each costs Blender a
    little per frame (about 1 µs: docs/performance-history.md). Returns how many (named `prefix` and a number, after those `driver` has)."""
    above = set()
    bones = armature.data.bones
    for name in names:
        b = bones.get(name)
        p = b.parent if b is not None else None
        while p is not None and p.name not in above:
            above.add(p.name)
            p = p.parent
    targets = []
    for name in names:
        b = bones.get(name)
        if b is None:
            continue
        if b.bbone_segments > 1:
            targets.append((name, "bbone_easein"))
        elif name not in above:
            targets.append((name, "matrix"))
    start = len(driver.variables)
    for i, (name, prop) in enumerate(targets):
        v = driver.variables.new()
        v.name, v.type = f"{prefix}{start + i}", "SINGLE_PROP"
        v.targets[0].id = armature
        v.targets[0].data_path = f"pose.bones[{_quoted(name)}].{prop}"
    return len(targets)


def _quoted(name: str) -> str:
    return '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'
