// twin layer — run records on disk: trajectory CSV, JSON documents, the event log.
//
// Records must be complete or absent, never half-written under their final name: the CSV
// and JSON writers write "DIR/.NAME.part" and rename it to NAME on close (rename within one
// directory is atomic), and every write is checked so a full disk or an unwritable
// directory is a clear std::runtime_error naming the path rather than a silently short
// file. Numbers are formatted as printf's "%.10g", so identical runs give identical bytes.
// The run loop writes the CSVs and the event log at control-sample rate: those files are
// write-behind (bus_emulators/write_behind.hpp), so a row costs a copy into memory and a disk
// that throttles writers (much dirty page cache) does not stall a realtime loop; a write
// error then shows at a later row, flush or close. One-shot documents are written plainly.
#pragma once

#include <nlohmann/json.hpp>

#include "bus_emulators/write_behind.hpp"

#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace omnitwin::twin {

// A C stdio file whose every operation is checked; errors throw std::runtime_error naming
// the path. Closed (without throwing) by the destructor.
class CheckedFile {
 public:
  // A plain stdio file.
  CheckedFile(std::string path, const char* mode);
  // Write-behind: bytes reach the disk from a thread of the file's own (see above), through
  // the options' encoder if it has one; close() waits for them and reports their errors.
  CheckedFile(std::string path, const char* mode, const bus_emulators::WriteBehindOptions& behind);
  ~CheckedFile();
  CheckedFile(const CheckedFile&) = delete;
  CheckedFile& operator=(const CheckedFile&) = delete;

  void write(std::string_view text);
  void flush();
  void close();  // flushes; idempotent
  bool is_open() const { return f_ != nullptr; }
  bool failed() const { return failed_; }  // some operation threw
  const std::string& path() const { return path_; }

 private:
  [[noreturn]] void fail(const char* what, int err);

  std::string path_;
  std::FILE* f_ = nullptr;
  std::unique_ptr<bus_emulators::WriteBehindFile> behind_;  // set: f_ is its stream
  bool failed_ = false;
};

// A CSV file written through DIR/.NAME.part and renamed to DIR/NAME by close().
class CsvWriter {
 public:
  // Creates the temp file for `path` (DIR/NAME) and writes the header line. Throws
  // std::runtime_error if it cannot be created (missing or unwritable directory).
  CsvWriter(const std::string& path, const std::vector<std::string>& header);
  // The same for DIR/NAME given as its two parts.
  CsvWriter(const std::string& dir, const std::string& name, const std::vector<std::string>& header);
  // Closes (and renames) if still open; errors are logged, not thrown.
  ~CsvWriter();
  CsvWriter(const CsvWriter&) = delete;
  CsvWriter& operator=(const CsvWriter&) = delete;

  // One line: each value as "{:.10g}", comma-separated. values.size() must equal the
  // header's column count (std::invalid_argument otherwise: a programmer error). Returns
  // false when the write failed (e.g. disk full; error() says why): this is on the run's
  // cyclic path, so a failure is a status, not an exception. Allocation-free once warm.
  bool row(std::span<const double> values);
  // Why the last failed write failed ("" if none did).
  const std::string& error() const { return error_; }
  // Pushes buffered rows to the temp file (still under its temp name).
  void flush();
  // Flushes, closes and renames the temp file to its final name. Idempotent. If a write
  // failed earlier the temp file is closed but not renamed, and this throws.
  void close();

  const std::string& path() const { return path_; }  // the final name
  std::size_t rows() const { return rows_; }

 private:
  std::string path_;
  CheckedFile file_;
  std::size_t columns_;
  std::size_t rows_ = 0;
  std::string line_;  // reused per row: its staged form (see records.cpp, CsvEncoder)
  std::string error_;
};

// Writes `text` to path via "<dir>/.<name>.part" + rename. Throws std::runtime_error.
void write_text_atomic(const std::string& path, std::string_view text);

// Writes `j` pretty-printed (2-space indent, trailing newline) atomically as above.
void write_json_atomic(const std::string& path, const nlohmann::json& j);

// The run's event log (DIR/events.log): one line per event, "%12.6f  %-10s  %s" (sim time
// [s], kind, message), committed per line, so it reaches the file within the write-behind
// period (20 ms) and survives a crash but for that. Like every record it is
// written as DIR/.events.log.part (read that one while a run is going) and renamed by close().
class EventLog {
 public:
  // Creates (truncates) the temp file for `path`, normally DIR/events.log. Throws
  // std::runtime_error if it cannot.
  explicit EventLog(const std::string& path);
  // Closes (and renames) if still open; errors are logged, not thrown.
  ~EventLog();
  EventLog(const EventLog&) = delete;
  EventLog& operator=(const EventLog&) = delete;

  // Appends one event; newlines in `message` become spaces. Returns false when the write
  // failed (error() says why): events are logged from the cyclic path.
  bool log(double sim_time_s, std::string_view kind, std::string_view message);
  const std::string& error() const { return error_; }
  // Closes and renames the temp file to its final name. Idempotent. If a write failed the
  // temp file keeps its name, and this throws std::runtime_error.
  void close();

  const std::string& path() const { return path_; }  // the final name

 private:
  std::string path_;
  CheckedFile file_;
  std::string error_;
};

}  // namespace omnitwin::twin
