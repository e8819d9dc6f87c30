// Shared by the study commands: the output folder, replacing writes and --link's conditions.
#pragma once

#include "net/link_emulator.h"
#include "study/commands.h"

#include <filesystem>
#include <string>

namespace trephine::study {

// Makes `out` (with its parents) and checks that a file can be written there, before a study
// runs: a folder that takes no files would otherwise be found only once the study had run.
std::string makeOutDir(const std::string& out);

// Through a temporary file renamed over `path` once complete: a failed write (a full disk) leaves
// an earlier run's file whole.
void writeText(const std::filesystem::path& path, const std::string& text);

// --link's conditions for a study. A loss of 100 % is refused: nothing would get through and the
// study would wait out its timeouts.
net::LinkConditions studyLink(const std::string& text);

// Throws what runUpdatesStudy would for these options on `volume`, without running anything.
void checkUpdatesOptions(const UpdatesOptions& o, const Volume& volume);

} // namespace trephine::study
