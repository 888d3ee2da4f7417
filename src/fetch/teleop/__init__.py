"""Collecting demonstrations: devices (gamepad, keyboard, scripted, expert), the control loop, the viewer."""
