"""Colours that mean one thing in every view of a run (the report's charts, an experiment's results, the
Foxglove scene): robot states, and what became of frames."""

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

OUTCOME_COLOURS = {
    "sent": "#4c72b0",
    "delivered": "#55a868",
    "collided": "#c44e52",
    "lost": "#8c8c8c",
    "mac_retries": "#dd8452",
}
"""What became of frames (a node's counters) and its colour: delivered green, collided red, lost grey."""
