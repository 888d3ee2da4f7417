"""Re-simulating saved demos bit for bit and rendering a dataset's saved states into it: `gym-fetch replay`,
`info` (one reader per recorded format) and `render-obs`."""
