"""The scene: beacons, LEDs, diffusers, environments and the viewing camera's geometry,
assembled into Mitsuba scenes and rendered to spectral radiance on a camera's pixel grid."""
