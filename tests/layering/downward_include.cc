// Compiled as part of the render module: its own headers and core's resolve
// (test layering.downward_include_compiles, the control of the upward one).
#include "ar/render/rasterizer.h"
#include "core/mesh.h"

int LayeringProbeDownward() { return 0; }
