# SPDX-License-Identifier: GPL-3.0-or-later
"""Where artists find the weighting operators: Object > Parent (beside With Automatic Weights)
and the DQ Skin panel."""

from __future__ import annotations


def draw_parent_entries(self, context):
    """Object > Parent: DQ Skin's automatic weights and weight transfer."""
    layout = self.layout
    layout.separator()
    layout.operator("object.dq_skin_automatic_weights", text="With Automatic Weights (DQ Skin)", icon="MOD_ARMATURE")
    layout.operator("object.dq_skin_transfer_weights", text="Transfer Weights to Clothing (DQ Skin)", icon="MOD_CLOTH")


def draw_panel_row(layout) -> None:
    """The two operators in one row of the DQ Skin panel."""
    row = layout.row(align=True)
    row.operator("object.dq_skin_automatic_weights", text="Automatic Weights", icon="MOD_ARMATURE")
    row.operator("object.dq_skin_transfer_weights", text="Transfer to Clothing", icon="MOD_CLOTH")
