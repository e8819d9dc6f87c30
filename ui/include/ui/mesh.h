// The tool meshes a client draws over the DBI in pass 2, generated in code (no GL here, so tests
// check them headless): the drill handpiece with shaft and spherical burr, and the perforator.
// The surgical field's mesh comes from the server's scene (libsim/mesh.h builds it there).
#pragma once

#include "libsim/mesh.h"
#include "libsim/tool.h"

namespace trephine::ui {

// The meshes are libsim's (the server builds the surgical field); the names stay usable here.
using trephine::makeSurgicalField;
using trephine::MeshData;
using trephine::MeshVertex;

// Tool-local frame as libsim's ToolShape: origin at the burr centre (perforator: the tip's apex),
// shaft along +z. The handpiece body uses the owner's colour.
MeshData makeToolMesh(const ToolShape& shape);

} // namespace trephine::ui
