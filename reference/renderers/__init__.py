"""The renderers the tracer is judged against: Mitsuba 3 (the reference) and
LuxCoreRender (a third vote)."""
