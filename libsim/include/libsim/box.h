// Integer 3D boxes of voxels: the tight box of changed voxels (BB_volume) and friends.
// A box is half-open: it holds voxels with lo <= v < hi on every axis. An empty box has lo >= hi.
#pragma once

#include <algorithm>
#include <cstdint>
#include <glm/common.hpp>
#include <glm/vec3.hpp>
#include <limits>

namespace trephine {

struct Box3i {
    glm::ivec3 lo{std::numeric_limits<int>::max()};
    glm::ivec3 hi{std::numeric_limits<int>::min()};

    static Box3i fromMinMax(glm::ivec3 lo, glm::ivec3 hiExclusive) { return {lo, hiExclusive}; }

    bool empty() const { return lo.x >= hi.x || lo.y >= hi.y || lo.z >= hi.z; }
    glm::ivec3 size() const { return empty() ? glm::ivec3(0) : hi - lo; }
    int64_t count() const {
        glm::ivec3 s = size();
        return int64_t(s.x) * s.y * s.z;
    }
    bool contains(glm::ivec3 v) const {
        return v.x >= lo.x && v.y >= lo.y && v.z >= lo.z && v.x < hi.x && v.y < hi.y && v.z < hi.z;
    }
    // Grows the box to hold voxel v.
    void extend(glm::ivec3 v) {
        lo = glm::min(lo, v);
        hi = glm::max(hi, v + 1);
    }
    // Grows the box to hold all of o (an empty o changes nothing).
    void merge(const Box3i& o) {
        if (o.empty())
            return;
        if (empty()) {
            *this = o;
            return;
        }
        lo = glm::min(lo, o.lo);
        hi = glm::max(hi, o.hi);
    }
    Box3i intersect(const Box3i& o) const { return {glm::max(lo, o.lo), glm::min(hi, o.hi)}; }
    bool operator==(const Box3i& o) const {
        return (empty() && o.empty()) || (lo == o.lo && hi == o.hi);
    }
};

} // namespace trephine
