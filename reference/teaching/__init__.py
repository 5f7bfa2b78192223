"""The lectures' tools: Heckbert's minray (minray), the first assignment (assignment),
runtime against depth (depth_sweep), ray trees and light paths (paths), Fresnel curves
(fresnel_curves)."""
