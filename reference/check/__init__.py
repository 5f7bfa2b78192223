"""Another renderer's image judged: `whitted check` (judge), reading users' images
(images), naming the suspect formula bug (suspects), and suites handed out and graded
(suite)."""
