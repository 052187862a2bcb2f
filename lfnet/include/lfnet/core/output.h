// Writing outputs safely (docs/robustness.md, "Outputs"): files and folders appear whole or not
// at all, an output never overlaps an input, an existing output is replaced only on request and
// never deleted before its replacement is complete, and two writers never share one output.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace lfnet {

// The temporary sibling a writer of `target` uses: `.<stem>.tmp<pid><extension>` in the same
// folder (the extension is kept, so writers that pick a format by name still do).
std::filesystem::path temporary_path(const std::filesystem::path& target);

// Cleans up after writers of `target` that are no longer running (a live writer's files are left
// alone): removes their temporaries, and puts back what an interrupted replacement had moved
// aside: a run that `--force` replaced (RunFolder) whose new run never reached its first
// checkpoint, or a folder whose swap (write_folder) was cut between its two renames. Returns
// whether something was put back.
bool remove_stale_temporaries(const std::filesystem::path& target);

// Writes the file `target` through `write(temporary)`, then renames it into place, so `target`
// is never half-written. On failure the temporary is removed and the error passed on (an IoError
// on a full file system gains the system's reason, which image libraries leave out). With
// `durable`, the file and its folder are synced to disk before returning.
void write_file_atomically(const std::string& target,
                           const std::function<void(const std::string& temporary)>& write,
                           bool durable = false);

// Writes `bytes` to the file `target` atomically (write_file_atomically); a failure names the
// file and the system's reason ("No space left on device").
void write_bytes_file(const std::string& target, std::string_view bytes, bool durable = false);
// The same for the concatenation of `pieces`, which is never made (a large page need not be
// held twice).
void write_pieces_file(const std::string& target, const std::vector<std::string_view>& pieces,
                       bool durable = false);

// Writes `text` to the file `target` atomically.
void write_text_file(const std::string& target, const std::string& text);

// Writes all of `data` to the open file `fd` (retrying short writes); a failure throws IoError
// naming `path` and the system's reason.
void write_all(int fd, std::string_view data, const std::string& path);

// Refuses (ConfigError naming `option`) an output that is, contains or lies inside one of
// `inputs` (files or folders; empty entries are ignored).
void check_output_apart(const std::string& output, const std::vector<std::string>& inputs,
                        const std::string& option = "--out");

// An exclusive lock on one output path, held while the object lives: a second writer of the
// same output (in this process or another) fails at once with a ConfigError. The lock is a
// hidden `.<name>.lock` file beside the output, removed on release, with the folders it had to
// make for it if they are still empty (the output never came).
class OutputLock {
 public:
  explicit OutputLock(const std::string& output, const std::string& option = "--out");
  ~OutputLock();
  OutputLock(const OutputLock&) = delete;
  OutputLock& operator=(const OutputLock&) = delete;

 private:
  std::string path_;
  int fd_ = -1;
  std::filesystem::path made_;  // the outermost folder the lock made, if any
};

// What a command writes into one output folder.
struct OutputFolderPolicy {
  std::string option = "--out";     // the option that named it, for messages
  bool force = false;               // replace an existing non-empty folder
  std::vector<std::string> inputs;  // what the command reads: never overwritten
};

// The policy's checks alone (a command calls it before its work, so a refusal costs nothing):
// apart from the inputs, a folder, empty unless `force`.
void check_output_folder(const std::string& out, const OutputFolderPolicy& policy);

// The checks for one output file: apart from the inputs, not a folder, and absent or empty
// unless `force`.
void check_output_file(const std::string& out, const OutputFolderPolicy& policy);

// Refuses an input that exists but is not a regular file, before anything opens it: reading a
// FIFO, socket or device may block forever, and a folder is no file. An IoError naming `path`
// (the caller adds its flag); a missing path is left to the reader, which names it.
void check_regular_input(const std::string& path);

// Splits a comma-separated list of paths (e.g. --sensor a.tif,b.tif) for the inputs of a policy.
std::vector<std::string> split_paths(const std::string& list);

// Writes the folder `out` through `write(temporary folder)`: checks the policy, takes the
// output's lock, removes dead writers' temporaries, builds the new folder beside `out` and
// swaps it in. An existing `out` is kept until the new one is complete.
void write_folder(const std::string& out, const OutputFolderPolicy& policy,
                  const std::function<void(const std::string& dir)>& write);

// An output folder written as the work goes (training runs, batches). The constructor checks
// the policy and takes the lock. An existing non-empty folder is refused unless `force` (start
// afresh: the old folder is moved aside, and removed by commit()) or `resume` (continue in it).
// Destroyed without commit(), for a run that failed before anything lasting was written, it
// removes the folder it created and puts the old one back: a failed start leaves nothing.
class RunFolder {
 public:
  RunFolder(const std::string& dir, const OutputFolderPolicy& policy, bool resume = false);
  ~RunFolder();
  RunFolder(const RunFolder&) = delete;
  RunFolder& operator=(const RunFolder&) = delete;

  // The run has written something that lasts (a checkpoint, a record): keep it from now on.
  void commit();
  const std::string& path() const { return dir_; }

 private:
  std::string dir_;
  OutputLock lock_;
  bool created_ = false;         // the folder did not exist (or was moved aside)
  std::filesystem::path aside_;  // where the replaced folder waits for commit()
  bool committed_ = false;
};

}  // namespace lfnet
