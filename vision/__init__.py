"""Camera -> numbers: frame sources, drum ROI, colour classes, mixing indices.

Pure NumPy/OpenCV; imports nothing from ``sim``, ``control`` or ``twin``.
"""
