// bus_emulators — write-behind files: a C stdio FILE* whose bytes go to memory, and a
// background thread of the file's own that writes them to disk. Header-only.
//
// Why: a realtime run writes its records (pcap, trajectory CSV, event log) on the run loop,
// and write(2) on a file blocks for milliseconds while the kernel throttles writers because
// the machine holds much dirty page cache (balance_dirty_pages), which a build or a test suite
// beside the run easily causes (measured: docs/reliability.md, "soak.can_short"). A loop that
// blocks there misses ticks and the bus's deadlines. Here the loop only copies into memory;
// the thread takes whole buffers and blocks in write(2) in its place.
//
// The stream comes from fopencookie, so callers keep fwrite/fputs (and libpcap's
// pcap_dump_fopen). Bytes move in three steps: stdio's buffer → the file's staging buffer
// (the caller's thread only, no lock) → commit() hands the staged bytes to the writer thread
// (a short mutex) → write(2) within `period` (20 ms), or at once when 64 KiB wait. commit()
// is the record boundary: the thread writes only committed bytes, so a reader of the file, or
// a SIGKILL, sees whole records up to a commit (a burst of more than 64 KiB between commits is
// handed over early, cut wherever stdio cut it, as plain stdio would). A SIGKILL loses what
// was not written yet: the last period's records. The first write error (ENOSPC) is kept:
// from then on writes fail (ferror, errno the system's code), commit() returns false, and
// close() returns EOF with errno.
#pragma once

#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

namespace omnitwin::bus_emulators {

struct WriteBehindOptions {
  bool fsync_on_close = false;           // fsync(2) before close(2)
  std::chrono::milliseconds period{20};  // the writer's longest sleep
  std::size_t wake_bytes = 64 * 1024;    // staged bytes that are committed and written at once
  // Optional, run on the writer thread: turns the bytes the caller wrote (in, n) into the
  // bytes the file gets, appended to `out` (e.g. binary rows into CSV text, so formatting
  // leaves the caller's loop too). Called with whatever was committed, which may end inside
  // one of the caller's records: an encoder keeps such a tail for its next call.
  std::function<void(const char* in, std::size_t n, std::vector<char>& out)> encode{};
};

// One write-behind file. States: closed (default, or after close()) → open (open() succeeded:
// thread running, stream() valid) → closed. Not copyable or movable (the thread holds `this`).
class WriteBehindFile {
 public:
  WriteBehindFile() = default;
  ~WriteBehindFile() { close(); }
  WriteBehindFile(const WriteBehindFile&) = delete;
  WriteBehindFile& operator=(const WriteBehindFile&) = delete;

  // Opens `path` for writing ("w…": create or truncate; "a…": append) and starts the writer
  // thread. False with errno set when the file cannot be opened or the thread not started.
  // Not real-time safe.
  bool open(const std::string& path, const char* mode, const WriteBehindOptions& o = {}) {
    if (f_) close();
    const bool append = mode[0] == 'a';
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC | (append ? O_APPEND : O_TRUNC), 0644);
    if (fd_ < 0) return false;
    opt_ = o;
    err_ = 0;
    failed_ = false;
    closing_ = false;
    staging_.reserve(opt_.wake_bytes + 16 * 1024);  // steady state: no allocation per write
    front_.reserve(256 * 1024);
    back_.reserve(256 * 1024);
    if (opt_.encode) encoded_.reserve(1024 * 1024);
    if (!start_thread()) return abandon(errno);
    const cookie_io_functions_t io{nullptr, &WriteBehindFile::cookie_write, nullptr, nullptr};
    f_ = fopencookie(this, append ? "a" : "w", io);
    if (!f_) return abandon(errno);
    return true;
  }

  bool is_open() const { return f_ != nullptr; }
  // The stdio stream (nullptr when closed). Its writes copy into memory.
  std::FILE* stream() const { return f_; }

  // Flushes stdio and hands every staged byte to the writer thread: a record boundary. False
  // with errno set once a write failed. Real-time safe (no system call but an occasional futex
  // wake; allocation only when a burst outgrows the reserved buffers).
  bool commit() {
    if (!f_) return false;
    if (std::fflush(f_) != 0) return failed_errno();
    hand_over();
    return err_ == 0 || failed_errno();
  }

  // Commits, waits for the thread to write everything, fsyncs when asked and closes the file.
  // 0, or EOF with errno set to the first error. Idempotent. Not real-time safe.
  int close() {
    if (!f_) return 0;
    std::fclose(f_);  // its final flush lands in staging (errors are kept in err_)
    f_ = nullptr;
    hand_over();
    {
      std::lock_guard<std::mutex> lock(m_);
      closing_ = true;
    }
    cv_.notify_one();
    pthread_join(thread_, nullptr);
    int err = err_;
    if (err == 0 && opt_.fsync_on_close && ::fsync(fd_) != 0) err = errno;
    if (::close(fd_) != 0 && err == 0) err = errno;
    fd_ = -1;
    if (err == 0) return 0;
    errno = err;
    return EOF;
  }

 private:
  // stdio's write function: copy into staging; 0 (a stdio error) once the thread failed.
  static ssize_t cookie_write(void* self, const char* buf, size_t size) {
    auto* w = static_cast<WriteBehindFile*>(self);
    if (const int err = w->err_.load(std::memory_order_relaxed); err != 0) {
      errno = err;
      return 0;
    }
    w->staging_.insert(w->staging_.end(), buf, buf + size);
    if (w->staging_.size() >= w->opt_.wake_bytes) w->hand_over();
    return static_cast<ssize_t>(size);
  }

  // Moves staging to the thread's side; wakes it when enough waits.
  void hand_over() {
    if (staging_.empty()) return;
    bool wake = false;
    {
      std::lock_guard<std::mutex> lock(m_);
      front_.insert(front_.end(), staging_.begin(), staging_.end());
      wake = front_.size() >= opt_.wake_bytes;
    }
    staging_.clear();
    if (wake) cv_.notify_one();
  }

  bool failed_errno() {
    errno = err_ != 0 ? err_.load() : (errno != 0 ? errno : EIO);
    return false;
  }

  // A small stack: a run that locks its memory (mlockall) locks every thread's stack too. An
  // ordinary time-shared thread even when opened from a SCHED_FIFO loop (threads inherit the
  // policy by default): it must never compete with the loop it unburdens.
  bool start_thread() {
    pthread_attr_t attr;
    pthread_attr_init(&attr);
    pthread_attr_setstacksize(&attr, 128 * 1024);
    pthread_attr_setinheritsched(&attr, PTHREAD_EXPLICIT_SCHED);
    pthread_attr_setschedpolicy(&attr, SCHED_OTHER);
    sched_param sp{};
    sp.sched_priority = 0;
    pthread_attr_setschedparam(&attr, &sp);
    const int rc = pthread_create(&thread_, &attr, &WriteBehindFile::run, this);
    pthread_attr_destroy(&attr);
    if (rc != 0) errno = rc;
    return rc == 0;
  }

  // open() failed after the descriptor: release what was made; false with errno = err.
  bool abandon(int err) {
    if (f_ == nullptr && thread_ != pthread_t{}) {
      {
        std::lock_guard<std::mutex> lock(m_);
        closing_ = true;
      }
      cv_.notify_one();
      pthread_join(thread_, nullptr);
    }
    thread_ = pthread_t{};
    ::close(fd_);
    fd_ = -1;
    errno = err;
    return false;
  }

  static void* run(void* self) {
    static_cast<WriteBehindFile*>(self)->loop();
    return nullptr;
  }

  // Sleep until enough waits, a period passed or close(); swap; write outside the lock.
  void loop() {
    for (;;) {
      bool last = false;
      {
        std::unique_lock<std::mutex> lock(m_);
        cv_.wait_for(lock, opt_.period, [&] { return closing_ || front_.size() >= opt_.wake_bytes; });
        front_.swap(back_);
        last = closing_;
      }
      const std::vector<char>* bytes = &back_;
      if (opt_.encode && !back_.empty()) {
        encoded_.clear();
        opt_.encode(back_.data(), back_.size(), encoded_);
        bytes = &encoded_;
      }
      if (const int err = write_all(bytes->data(), bytes->size()); err != 0 && err_ == 0) err_ = err;
      back_.clear();
      if (last) return;  // close() handed over the final bytes before it asked
    }
  }

  // write(2) until done; the errno of the first failure, else 0. Nothing more after a failure.
  int write_all(const char* p, std::size_t n) {
    if (failed_) return 0;
    while (n > 0) {
      const ssize_t w = ::write(fd_, p, n);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) {
        failed_ = true;
        return w < 0 ? errno : EIO;
      }
      p += w;
      n -= static_cast<std::size_t>(w);
    }
    return 0;
  }

  std::FILE* f_ = nullptr;
  int fd_ = -1;
  WriteBehindOptions opt_;
  pthread_t thread_{};
  std::vector<char> staging_;  // the caller's thread only
  std::mutex m_;
  std::condition_variable cv_;
  std::vector<char> front_;  // under m_: committed, not yet taken by the thread
  std::vector<char> back_;   // the thread's: being written
  std::vector<char> encoded_;  // the thread's: back_ after opt_.encode
  bool closing_ = false;     // under m_
  std::atomic<int> err_{0};  // the first write error (set by the thread)
  bool failed_ = false;      // the thread's: a write failed, drop the rest
};

}  // namespace omnitwin::bus_emulators
