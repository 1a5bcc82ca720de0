// Compiled as part of the render module, which sits below the pipeline: this
// include must not resolve (test layering.upward_include_fails_to_compile).
#include "ar/pipeline/pipeline_options.h"

int LayeringProbeUpward() { return 0; }
