"""The simulated hardware in front of the firmware: two imagers behind real lenses (sensor), the
scenes they look at (scene) and the ray caster that renders them (render)."""
