# SPDX-License-Identifier: GPL-3.0-or-later
"""Which objects Blender evaluates in a scene's viewports on its own: those of the view layers'
collections that are neither excluded nor disabled in viewports (the monitor icon), unless the
object itself is disabled; objects hidden with the eye icon are still evaluated (so that they
show at once), and so is an object whose viewport visibility is animated or driven. This is
Blender's rule for the bases of a viewport's graph (`need_pull_base_into_graph`). What else pulls
an object in (a collection instance, a node's Object Info, a driver) is not read here: such an
object's own batch of the feed, which its carriers pull in with it, skins it there."""

from __future__ import annotations


def enabled_in_viewport(scene) -> set[int]:
    """Session uids of the objects in the collections `scene`'s viewports evaluate (every view
    layer, and the background sets')."""
    uids: set[int] = set()
    seen: set[int] = set()
    while scene is not None and scene.session_uid not in seen:
        seen.add(scene.session_uid)
        for layer in scene.view_layers:
            _collect(layer.layer_collection, uids)
        scene = scene.background_set
    return uids


def layout(scene) -> tuple:
    """What changes when a collection is excluded or included, cheaply read on every frame: the
    object count of each view layer (a script's change before a frame change reports no update
    of collections; the interface's does)."""
    return tuple(len(layer.objects) for layer in scene.view_layers)


def _collect(layer_collection, uids: set[int]) -> None:
    if layer_collection.exclude or layer_collection.collection.hide_viewport:
        return
    uids.update(obj.session_uid for obj in layer_collection.collection.objects)
    for child in layer_collection.children:
        _collect(child, uids)


def evaluated_on_its_own(obj, enabled: set[int]) -> bool:
    """Whether Blender evaluates `obj` in the viewport without anything pulling it in (`enabled`
    from `enabled_in_viewport`)."""
    if obj.session_uid in enabled and not obj.hide_viewport:
        return True
    return _visibility_animated(obj)


def _visibility_animated(obj) -> bool:
    """Its viewport visibility is driven or keyed (Blender keeps such objects in the graph);
    an action it cannot read, or NLA strips, count as animated."""
    ad = obj.animation_data
    if ad is None:
        return False
    if any(d.data_path == "hide_viewport" for d in ad.drivers):
        return True
    if len(ad.nla_tracks):
        return True
    action = ad.action
    if action is None:
        return False
    try:
        return any(fc.data_path == "hide_viewport" for fc in _fcurves(action))
    except (AttributeError, TypeError):
        return True


def _fcurves(action):
    layers = getattr(action, "layers", None)
    if layers is not None and len(layers):  # slotted actions (4.4 on): every slot's curves
        for layer in layers:
            for strip in layer.strips:
                for bag in strip.channelbags:
                    yield from bag.fcurves
        return
    yield from getattr(action, "fcurves", ())  # before slotted actions, or an empty one
