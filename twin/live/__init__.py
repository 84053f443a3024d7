"""The live loop's workers (camera, process, mill, twin, what-if, supervisor) and the
records they exchange. ``twin.loop.LiveLoop`` is their composition root: the only place
that starts and joins their threads."""
