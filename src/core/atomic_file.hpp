// strata — files written whole or not at all.
//
// Every file strata writes in one piece (status.json, checkpoints, ParaView frames,
// benchmark results, written models) goes through write_file_atomically: the contents go
// to a temporary name in the same folder (PATH.tmp.<pid>.<k>), are flushed to the disk
// (fsync), and the temporary is renamed onto PATH. rename(2) within one file system
// replaces PATH in one step, so a reader — or a run interrupted at any point — sees either
// the old file or the complete new one, never a partial file. (The Matrix Market writers
// in src/sparse/matrix_market.cpp do the same with their own gzip-capable writer.)
#pragma once

#include <string>
#include <string_view>

namespace strata {

/// Writes `contents` to `path` atomically (see above). `durable`: fsync before the rename
/// (survives a power loss too; false for many small files such as ParaView frames, which
/// are then atomic against interruption and readers only). Throws Error naming `path` and
/// the system's reason; the temporary is removed on failure.
void write_file_atomically(const std::string& path, std::string_view contents, bool durable = true);

/// Renames `from` onto `to` (replacing it); throws Error naming both on failure.
void rename_file(const std::string& from, const std::string& to);

}  // namespace strata
