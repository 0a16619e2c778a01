"""Robot states as colours, one palette for every view of a run (the report's charts, the Foxglove scene)."""

STATE_COLOURS = {
    "waiting": "#bbbbbb",
    "command-waiting": "#937860",
    "following": "#4c72b0",
    "leading": "#55a868",
    "remote-control": "#8172b2",
    "organizing": "#dd8452",
    "master-driving": "#c44e52",
    "slave-driving": "#da8bc3",
    "emergency": "#ff0000",
    "surround": "#64b5cd",
}
"""Each ``RobotState.label`` (and the surround law's state) and its colour."""
