#include "libsim/tool_catalogue.h"

#include <cassert>

namespace trephine {

// Each defined in its own file under libsim/src/tools/.
extern const ToolType kBurrTool, kPerforatorTool, kDiamondBurrTool;

namespace {

// The registry, by id: a new tool is one line here.
const ToolType* const kTools[] = {&kBurrTool, &kPerforatorTool, &kDiamondBurrTool};
static_assert(std::size(kTools) == kToolKindCount);

} // namespace

const ToolType& toolType(ToolKind kind) {
    assert(uint8_t(kind) < kToolKindCount && "toolType: check a kind read from outside first");
    return *kTools[uint8_t(kind) < kToolKindCount ? uint8_t(kind) : 0];
}

std::span<const ToolType* const> toolTypes() {
    return kTools;
}

std::optional<ToolKind> toolKindNamed(std::string_view name) {
    for (const ToolType* t : kTools)
        if (name == t->name)
            return t->kind;
    return std::nullopt;
}

} // namespace trephine
