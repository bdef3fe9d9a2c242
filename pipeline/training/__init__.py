"""Training code: Stage I inpainter (Lightning)."""
