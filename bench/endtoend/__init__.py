"""DQ Skin against Blender's Armature modifier, end to end, in one Blender session (see
`bench/blender_bench.py`): the scenes, the timing, the routes DQ Skin's positions can take into
Blender's evaluation, and the cases."""
