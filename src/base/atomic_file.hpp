// strata — files written whole or not at all, and never in place of what is not ours.
//
// Every file strata writes in one piece (solutions, status.json, checkpoints, ParaView
// frames, benchmark results, written models, Matrix Market files) goes through the rules
// here. The path is first resolved (resolve_output):
//
//   - a symbolic link is followed to its final target, and the target is what is written
//     (the link stays a link, as with a shell's `>` redirection);
//   - an existing file that is not a regular file (a character device such as /dev/null or
//     /dev/stdout, a FIFO) is written through in place: opened for writing, never
//     truncated, renamed or removed;
//   - a directory, a socket or a block device is refused;
//   - anything else (a regular file, or no file yet) is written atomically: the contents
//     go to a temporary name in the target's folder (TARGET.tmp.<pid>.<k>), are flushed to
//     the disk (fsync), and the temporary is renamed onto TARGET. rename(2) within one file
//     system replaces TARGET in one step, so a reader — or a run interrupted at any point —
//     sees either the old file or the complete new one, never a partial file.
//
// check_output_path makes the same decision before any expensive work and proves that the
// write can happen (the folder exists and a file can be created in it; a write-through
// target can be opened), so that a solve never runs for an hour to fail at its last step.
#pragma once

#include <string>
#include <string_view>

namespace strata {

/// Where a write to a path goes (see the header above).
struct OutputTarget {
  std::string path;            ///< the path written: the final target of any symbolic links
  bool write_through = false;  ///< an existing non-regular file, written in place
};

/// Resolves `path` for writing: follows symbolic links (at most 40) to the final target,
/// which need not exist yet. Throws Error naming `path` when the target is a directory, a
/// socket or a block device, when a link cannot be read, or when the links loop.
OutputTarget resolve_output(const std::string& path);

/// Checks, before the work whose result goes there, that `path` can be written: resolves
/// it (resolve_output), then for a write-through target checks the permission to write
/// (without opening it: a FIFO's reader would see end-of-file), and otherwise checks that the
/// target's folder exists and that a file can be created in it (by creating and removing a
/// temporary), and that an existing regular target is writable. Throws Error naming
/// `path` and the reason. Writes nothing that stays.
void check_output_path(const std::string& path);

/// Writes `contents` to `path` by the rules above. `durable`: fsync before the rename
/// (survives a power loss too; false for many small files such as ParaView frames, which
/// are then atomic against interruption and readers only). Throws Error naming `path` and
/// the system's reason; the temporary is removed on failure.
void write_file_atomically(const std::string& path, std::string_view contents, bool durable = true);

/// A temporary file name beside `target` (TARGET.tmp.<pid>.<k>, unique in this process).
std::string temporary_name(const std::string& target);

/// Moves the finished file `from` (a temporary or partial file strata wrote) onto `to`
/// by the rules above: renamed onto the final target of a link, copied into a
/// write-through target (and then removed). Throws Error naming both on failure.
void rename_file(const std::string& from, const std::string& to);

}  // namespace strata
