# SPDX-License-Identifier: GPL-3.0-or-later
"""How DQ Skin's positions reach Blender: the ways behind one interface (`base.Route`), and
the data-blocks of the add-on's own they use (result objects, fed point caches)."""
