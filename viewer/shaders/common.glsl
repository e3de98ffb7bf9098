// Shared helpers, inserted after the #version line of every compute shader that includes it.
// Global invocation index for 1D work dispatched as a 2D grid (at most 65535 groups per axis).
uint global_index() {
    return gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
}
