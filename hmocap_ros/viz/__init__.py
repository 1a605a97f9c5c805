"""Pictures and viewers: overlays of the tracked skeleton and gestures on the images, the Foxglove bridge."""
