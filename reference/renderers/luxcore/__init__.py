"""LuxCoreRender, the third renderer's vote: the scene conversion (scene), rendering in
a child process (render, runner), and the three-way verdict (vote)."""
