#pragma once
// The writer's lock on its shared-memory segment (docs/shm-format.md, "Writer liveness"):
// facecapd holds an open-file-description write lock on the whole segment for as long as
// it writes it. The kernel drops the lock when the writer's process ends, however it
// ends, so "lock held" means "a writer process owns this segment" even when it has stopped
// beating (stopped by SIGSTOP, hung), and "lock free" means the writer is gone. Readers
// only test the lock (F_OFD_GETLK), never take it. Only a write lock counts: a program that
// opened the segment read-only can take a read lock (lockf, F_RDLCK), which must neither
// pass for a live writer nor keep a restarted facecapd from its name.
//
// Header-only and libc-only: the client library and the daemon's writer both include it.
#include <cerrno>

#include <fcntl.h>

namespace facecap::shm {

inline struct flock whole_segment_lock(short type) noexcept {
  struct flock lock {};
  lock.l_type = type;
  lock.l_whence = SEEK_SET;  // l_start = l_len = 0: the whole segment, however it grows
  return lock;
}

// Takes the writer lock on `fd` (opened read-write) only if nobody holds it. Not RT-safe.
inline bool try_writer_lock(int fd) noexcept {
  struct flock lock = whole_segment_lock(F_WRLCK);
  return ::fcntl(fd, F_OFD_SETLK, &lock) == 0;
}

// Whether another open file description (a writer) holds a write lock on the segment `fd`
// refers to; `fd` may be read-only. Readers' read locks do not count. A failing query counts
// as held: never take a name from a writer that may be alive. Not RT-safe (one system call).
inline bool writer_lock_held(int fd) noexcept {
  struct flock lock = whole_segment_lock(F_WRLCK);
  if (::fcntl(fd, F_OFD_GETLK, &lock) != 0) return true;
  if (lock.l_type == F_WRLCK) return true;
  if (lock.l_type == F_UNLCK) return false;
  // A read lock conflicts first; F_OFD_GETLK names one conflicting lock: ask whether a
  // write lock is behind it by testing a read lock, which only a write lock conflicts with.
  lock = whole_segment_lock(F_RDLCK);
  if (::fcntl(fd, F_OFD_GETLK, &lock) != 0) return true;
  return lock.l_type != F_UNLCK;
}

}  // namespace facecap::shm
