// The instructors' marks on disk, beside a saved session's volume (`trephine server
// --save-on-exit OUT` writes OUT.marks; `--volume OUT` reads it back), so that the marks outlive
// the server as the drilled skull does. A text file, one mark a line:
//
//     trephine-marks 1
//     mark X Y Z "LABEL"
//
// X Y Z in mm (object space, as Annotate), LABEL quoted with \" \\ \n \t and \xHH escapes.
// Blank lines and lines starting with # are skipped.
#pragma once

#include "net/protocol.h"

#include <string>
#include <vector>

namespace trephine::net {

// The marks file that goes with a saved volume.
std::string marksPathFor(const std::string& volumePath);

// Writes the marks (id and author are not kept) through a ReplacingFile, so a failed write leaves
// any earlier file whole. Throws trephine::Error.
void writeMarksFile(const std::string& path, const std::vector<AnnotationInfo>& marks);

// Reads a marks file: ids 1..n in file order, author 0. Throws trephine::Error (one line, naming
// the file and the line) on anything malformed: a bad header, number, quote or escape, a position
// beyond kMaxAnnotationDistanceMm, a label longer than kMaxNameLength bytes, more than
// kMaxAnnotations marks.
std::vector<AnnotationInfo> readMarksFile(const std::string& path);

// Checks marks given to a server (ServerConfig::marks) as readMarksFile does; throws on the first
// that the wire could not carry.
void checkMarks(const std::vector<AnnotationInfo>& marks, const std::string& what);

} // namespace trephine::net
