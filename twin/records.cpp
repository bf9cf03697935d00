// twin layer — checked, atomic record files; see records.hpp.
#include "twin/records.hpp"

#include <fmt/format.h>

#include <charconv>
#include <spdlog/spdlog.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <stdexcept>

namespace omnitwin::twin {

namespace fs = std::filesystem;

namespace {

// "<dir>/.<name>.part" next to `path`, so the final rename stays within one file system.
std::string temp_path_for(const std::string& path) {
  const fs::path p(path);
  return (p.parent_path() / ("." + p.filename().string() + ".part")).string();
}

// Renames `from` to `to`; throws std::runtime_error naming both on failure.
void rename_checked(const std::string& from, const std::string& to) {
  std::error_code ec;
  fs::rename(from, to, ec);
  if (ec) throw std::runtime_error(fmt::format("cannot rename '{}' to '{}': {}", from, to, ec.message()));
}

// One CSV line: each value as "{:.10g}" (std::to_chars with 10 significant digits writes
// exactly what printf's %.10g does, at less than half the cost), comma-separated.
void append_csv_line(std::vector<char>& out, const double* v, std::size_t n) {
  char cell[64];
  for (std::size_t i = 0; i < n; ++i) {
    if (i) out.push_back(',');
    const auto r = std::to_chars(cell, cell + sizeof cell, v[i], std::chars_format::general, 10);
    out.insert(out.end(), cell, r.ptr);
  }
  out.push_back('\n');
}

// A CSV file's staged form, turned into text on its writer thread: 'H', a 4-byte length and
// the header line; or 'R' and one row's doubles. At a 1 ms control period formatting the rows
// was the largest cost of the run loop after the physics (issue 17's profile); here the loop
// copies the numbers and the other core formats them. Whatever a hand-over cuts off at its
// end waits in `pending` for the next.
struct CsvEncoder {
  std::size_t columns;
  std::vector<char> pending;
  std::vector<double> v;  // one row, copied out of `pending` (which need not be aligned)

  void operator()(const char* in, std::size_t n, std::vector<char>& out) {
    pending.insert(pending.end(), in, in + n);
    const std::size_t row_bytes = 1 + columns * sizeof(double);
    std::size_t at = 0;
    v.resize(columns);
    while (at < pending.size()) {
      if (pending[at] == 'H') {
        std::uint32_t len = 0;
        if (pending.size() - at < 1 + sizeof len) break;
        std::memcpy(&len, pending.data() + at + 1, sizeof len);
        if (pending.size() - at < 1 + sizeof len + len) break;
        const char* text = pending.data() + at + 1 + sizeof len;
        out.insert(out.end(), text, text + len);
        at += 1 + sizeof len + len;
      } else {
        if (pending.size() - at < row_bytes) break;
        std::memcpy(v.data(), pending.data() + at + 1, columns * sizeof(double));
        append_csv_line(out, v.data(), columns);
        at += row_bytes;
      }
    }
    pending.erase(pending.begin(), pending.begin() + static_cast<std::ptrdiff_t>(at));
  }
};

bus_emulators::WriteBehindOptions csv_options(std::size_t columns) {
  bus_emulators::WriteBehindOptions o;
  o.encode = CsvEncoder{columns, {}, {}};
  return o;
}

// A CSV header cell: quoted (with doubled quotes) only when it needs to be.
std::string csv_cell(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

}  // namespace

// ---------------------------------------------------------------------------------------
// CheckedFile

CheckedFile::CheckedFile(std::string path, const char* mode) : path_(std::move(path)) {
  f_ = std::fopen(path_.c_str(), mode);
  if (f_ == nullptr) fail("cannot create", errno);
}

CheckedFile::CheckedFile(std::string path, const char* mode, const bus_emulators::WriteBehindOptions& behind)
    : path_(std::move(path)), behind_(std::make_unique<bus_emulators::WriteBehindFile>()) {
  if (!behind_->open(path_, mode, behind)) fail("cannot create", errno);
  f_ = behind_->stream();
}

CheckedFile::~CheckedFile() {
  if (behind_) {
    behind_->close();
  } else if (f_ != nullptr) {
    std::fclose(f_);
  }
}

void CheckedFile::fail(const char* what, int err) {
  failed_ = true;
  throw std::runtime_error(fmt::format("{} '{}': {}", what, path_, std::strerror(err)));
}

void CheckedFile::write(std::string_view text) {
  if (f_ == nullptr) throw std::logic_error(fmt::format("write to closed file '{}'", path_));
  errno = 0;
  if (std::fwrite(text.data(), 1, text.size(), f_) != text.size() || std::ferror(f_)) {
    fail("cannot write", errno != 0 ? errno : EIO);
  }
}

void CheckedFile::flush() {
  if (f_ == nullptr) return;
  errno = 0;
  // Write-behind: a record boundary, handed to the writer thread (no system call).
  const bool ok = behind_ ? behind_->commit() : std::fflush(f_) == 0;
  if (!ok) fail("cannot write", errno != 0 ? errno : EIO);
}

void CheckedFile::close() {
  if (f_ == nullptr) return;
  // fclose flushes; a failure there (e.g. disk full) still releases the handle.
  std::FILE* f = f_;
  f_ = nullptr;
  errno = 0;
  const bool bad = std::ferror(f) != 0;
  // Write-behind: close() waits for the writer thread and reports its first error.
  const bool closed = behind_ ? behind_->close() == 0 : std::fclose(f) == 0;
  if (!closed || bad) fail("cannot write", errno != 0 ? errno : EIO);
}

// ---------------------------------------------------------------------------------------
// CsvWriter

CsvWriter::CsvWriter(const std::string& dir, const std::string& name,
                     const std::vector<std::string>& header)
    : CsvWriter((fs::path(dir) / name).string(), header) {}

CsvWriter::CsvWriter(const std::string& path, const std::vector<std::string>& header)
    : path_(path), file_(temp_path_for(path_), "wb", csv_options(header.size())), columns_(header.size()) {
  std::string line;
  for (std::size_t i = 0; i < header.size(); ++i) line += (i ? "," : "") + csv_cell(header[i]);
  line += "\n";
  const auto len = static_cast<std::uint32_t>(line.size());
  std::string staged = "H";
  staged.append(reinterpret_cast<const char*>(&len), sizeof len);
  file_.write(staged + line);
}

CsvWriter::~CsvWriter() {
  try {
    close();
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
  }
}

bool CsvWriter::row(std::span<const double> values) {
  if (values.size() != columns_) {
    throw std::invalid_argument(fmt::format("{}: row has {} values, header has {} columns", path_,
                                            values.size(), columns_));
  }
  // The numbers as they are ('R' and the doubles, into the reused buffer), one write: the
  // writer thread formats them (CsvEncoder).
  line_.assign(1, 'R');
  line_.append(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(double));
  try {
    file_.write(line_);
  } catch (const std::runtime_error& e) {
    error_ = e.what();  // cold path: the file is marked failed and will not be renamed
    return false;
  }
  ++rows_;
  return true;
}

void CsvWriter::flush() { file_.flush(); }

void CsvWriter::close() {
  if (!file_.is_open()) return;
  // A file that lost rows must never appear under the final name.
  const bool lost_rows = file_.failed();
  file_.close();
  if (lost_rows) throw std::runtime_error(fmt::format("'{}' left incomplete: a write failed", file_.path()));
  rename_checked(file_.path(), path_);
}

// ---------------------------------------------------------------------------------------
// JSON and plain text

void write_text_atomic(const std::string& path, std::string_view text) {
  const std::string temp = temp_path_for(path);
  try {
    CheckedFile f(temp, "wb");
    f.write(text);
    f.close();
    rename_checked(temp, path);
  } catch (const std::runtime_error&) {
    // Nothing half-written is left behind, not even under the temporary name.
    std::remove(temp.c_str());
    throw;
  }
}

void write_json_atomic(const std::string& path, const nlohmann::json& j) {
  write_text_atomic(path, j.dump(2) + "\n");
}

// ---------------------------------------------------------------------------------------
// EventLog

EventLog::EventLog(const std::string& path) : path_(path), file_(temp_path_for(path), "wb", bus_emulators::WriteBehindOptions{}) {}

EventLog::~EventLog() {
  try {
    close();
  } catch (const std::exception& e) {
    spdlog::warn("{}", e.what());
  }
}

bool EventLog::log(double sim_time_s, std::string_view kind, std::string_view message) {
  std::string line = fmt::format("{:12.6f}  {:<10}  {}\n", sim_time_s, kind, message);
  // Keep one event per line whatever the message holds.
  for (std::size_t i = 0; i + 1 < line.size(); ++i) {
    if (line[i] == '\n' || line[i] == '\r') line[i] = ' ';
  }
  try {
    file_.write(line);
    file_.flush();
  } catch (const std::runtime_error& e) {
    error_ = e.what();
    return false;
  }
  return true;
}

void EventLog::close() {
  if (!file_.is_open()) return;
  // A log that lost lines keeps its temporary name: it is not the run's whole log.
  const bool lost = file_.failed();
  file_.close();
  if (lost) throw std::runtime_error(fmt::format("'{}' left incomplete: a write failed", file_.path()));
  rename_checked(file_.path(), path_);
}

}  // namespace omnitwin::twin
