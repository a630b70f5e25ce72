// The RIB primitives (RI spec 3.2, sec. 5): Patch and PatchMesh in any basis, NuPatch and
// SubdivisionMesh, each converted to bicubic Bezier patches in world space and added to the scene
// with the attributes of the current graphics state. One object id per request.
#pragma once
#include "io/rib_graphics_state.h"
#include "io/rib_params.h"
#include "io/rib_request.h"
#include "scene/scene.h"

namespace tessera::rib {

// What a primitive request reads and where its patches go.
struct PrimitiveContext {
    Scene& scene;
    const GraphicsState& state;
    const Declarations& decls;
    Diagnostics& diag;
};

void readPatch(const Request& r, const PrimitiveContext& c);
void readPatchMesh(const Request& r, const PrimitiveContext& c);
void readNuPatch(const Request& r, const PrimitiveContext& c);
void readSubdivisionMesh(const Request& r, const PrimitiveContext& c);

}  // namespace tessera::rib
