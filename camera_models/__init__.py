"""What a camera does to light: lens, sensor, image processing and exposure control."""
