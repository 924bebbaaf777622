"""The scene: beacons, LEDs, diffusers, environments and the viewing camera's geometry,
assembled into Mitsuba scenes and rendered to spectral radiance on a camera's pixel grid."""

from scenes.tool_caches import place_tool_caches

place_tool_caches()  # before anything imports Dr.Jit or Matplotlib: their caches go under the cache folder
