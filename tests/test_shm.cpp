// The shared-memory ring: layout, seqlock under a concurrent writer, read-next with
// lapping, restarted and stale writers, permissions.
#include <atomic>
#include <csignal>
#include <cstring>
#include <fstream>
#include <thread>

#include <catch2/catch.hpp>
#include <fmt/format.h>
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "client/facecap_client.hpp"
#include "client/facecap_shm_lock.hpp"
#include "core/error.hpp"
#include "core/time.hpp"
#include "outputs/shm/shm_writer.hpp"

using namespace facecap;
using outputs::ShmOutputSpec;
using outputs::ShmWriter;

namespace {

std::string unique_name(const std::string& what) {
  static int counter = 0;
  return fmt::format("facecap-test-{}-{}-{}", ::getpid(), what, counter++);
}

ShmOutputSpec spec(const std::string& name, uint32_t shapes = 4, uint32_t vertices = 10, uint32_t slots = 4) {
  ShmOutputSpec s;
  s.name = name;
  for (uint32_t i = 0; i < shapes; ++i) s.shape_names.push_back(fmt::format("shape{}", i));
  s.vertex_count = vertices;
  s.slot_count = slots;
  s.nominal_rate_hz = 120.0;
  s.rig_name = "testrig";
  s.rig_hash = 42;
  return s;
}

// Every weight and coordinate of frame n is n plus its index: a torn read mixes frames.
SolvedFrame frame_with_pattern(int64_t n, Eigen::Index shapes, Eigen::Index vertices) {
  SolvedFrame f;
  f.resize(shapes, vertices);
  f.frame_no = n;
  f.receive_time_ns = 1000 + n;
  for (Eigen::Index i = 0; i < shapes; ++i) f.weights[i] = float(n) + float(i) * 0.25f;
  for (Eigen::Index i = 0; i < f.vertices.size(); ++i) f.vertices.data()[i] = float(n) + float(i);
  return f;
}

bool frame_is_consistent(const facecap_frame& f) {
  const auto n = float(f.frame_no);
  for (uint32_t i = 0; i < f.shape_count; ++i)
    if (f.weights[i] != n + float(i) * 0.25f) return false;
  for (uint32_t i = 0; i < f.vertex_count * 3; ++i)
    if (f.vertices[i] != n + float(i)) return false;
  return f.receive_time_ns == 1000 + f.frame_no;
}

}  // namespace

TEST_CASE("a published frame reads back exactly with the shapes and header the writer set") {
  const std::string name = unique_name("roundtrip");
  ShmWriter writer(spec(name));
  client::Subscriber reader(name);
  CHECK(reader.shape_count() == 4);
  CHECK(reader.shape_name(2) == "shape2");
  CHECK(reader.shape_name(4).empty());
  CHECK(reader.vertex_count() == 10);
  CHECK(reader.rig_name() == "testrig");
  CHECK(reader.writer_pid() == ::getpid());
  CHECK(reader.nominal_rate_hz() == 120.0);

  facecap_frame f{};
  CHECK(reader.read_latest(f) == FACECAP_NO_FRAME);
  SolvedFrame solved = frame_with_pattern(7, 4, 10);
  solved.head_rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitY()));
  solved.head_translation = Eigen::Vector3d(1, 2, 3);
  solved.flags = kSolvedHeadPoseHeld;
  const int64_t published = writer.publish(solved);
  REQUIRE(reader.read_next(f) == FACECAP_OK);
  CHECK(f.sequence == 1);
  CHECK(f.dropped == 0);
  CHECK(f.frame_no == 7);
  CHECK(f.publish_time_ns == published);
  CHECK(frame_is_consistent(f));
  CHECK(f.head_rotation_wxyz[0] == Approx(std::cos(0.25)));
  CHECK(f.head_rotation_wxyz[2] == Approx(std::sin(0.25)));
  CHECK(f.head_translation[2] == 3.0f);
  CHECK(f.flags == kSolvedHeadPoseHeld);
  CHECK(reader.read_next(f) == FACECAP_NO_FRAME);
  CHECK(reader.read_latest(f) == FACECAP_OK);
  CHECK(f.frame_no == 7);
}

TEST_CASE("read_next reports frames lost when the writer laps a slow reader") {
  const std::string name = unique_name("lapped");
  ShmWriter writer(spec(name, 2, 0, 4));
  client::Subscriber reader(name);
  for (int64_t n = 1; n <= 3; ++n) writer.publish(frame_with_pattern(n, 2, 0));
  facecap_frame f{};
  REQUIRE(reader.read_next(f) == FACECAP_OK);
  CHECK(f.frame_no == 1);
  for (int64_t n = 4; n <= 20; ++n) writer.publish(frame_with_pattern(n, 2, 0));
  // 20 published, the ring holds the last 4; the oldest the writer is not about to reuse is 18.
  REQUIRE(reader.read_next(f) == FACECAP_OK);
  CHECK(f.frame_no == 18);
  CHECK(f.dropped == 16);
  CHECK(f.vertices == nullptr);
  REQUIRE(reader.read_next(f) == FACECAP_OK);
  CHECK(f.frame_no == 19);
  CHECK(f.dropped == 0);
}

TEST_CASE("readers never see a torn frame while the writer publishes flat out") {
  const std::string name = unique_name("seqlock");
  ShmWriter writer(spec(name, 64, 2000, 2));  // two slots: the writer is always close behind a reader
  client::Subscriber reader(name);
  std::atomic<bool> done{false};
  constexpr int64_t kFrames = 20000;
  std::thread writer_thread([&] {
    SolvedFrame f = frame_with_pattern(0, 64, 2000);
    for (int64_t n = 1; n <= kFrames; ++n) {
      f = frame_with_pattern(n, 64, 2000);
      writer.publish(f);
    }
    done = true;
  });
  uint64_t reads = 0, contended = 0, torn = 0;
  int64_t last = 0;
  bool monotonic = true;
  facecap_frame f{};
  while (!done.load()) {
    const int status = reader.read_latest(f);
    if (status == FACECAP_ERR_CONTENDED) ++contended;
    if (status != FACECAP_OK) continue;
    ++reads;
    torn += frame_is_consistent(f) ? 0 : 1;
    monotonic = monotonic && f.frame_no >= last;
    last = f.frame_no;
  }
  writer_thread.join();
  INFO("reads " << reads << " contended " << contended);
  CHECK(reads > 100);
  CHECK(torn == 0);
  CHECK(monotonic);
}

TEST_CASE("a reader follows a restarted writer and sees its new shapes") {
  const std::string name = unique_name("restart");
  auto first = std::make_unique<ShmWriter>(spec(name, 3, 0, 4));
  first->publish(frame_with_pattern(1, 3, 0));
  client::Subscriber reader(name);
  CHECK(reader.check_writer(kNsPerSecond) == FACECAP_OK);
  first.reset();  // clean stop: marked stopped and unlinked
  CHECK(reader.check_writer(kNsPerSecond) == FACECAP_ERR_WRITER_GONE);
  facecap_frame f{};
  CHECK(reader.read_next(f) == FACECAP_NO_FRAME);

  ShmWriter second(spec(name, 5, 0, 4));
  CHECK(reader.check_writer(kNsPerSecond) == FACECAP_RESTARTED);
  CHECK(reader.shape_count() == 5);
  second.publish(frame_with_pattern(9, 5, 0));
  REQUIRE(reader.wait_next(f, kNsPerSecond) == FACECAP_OK);
  CHECK(f.frame_no == 9);
  CHECK(f.shape_count == 5);
  CHECK(frame_is_consistent(f));
}

TEST_CASE("a reader tells a writer that stopped beating but lives from one that is gone") {
  const std::string name = unique_name("stale");
  auto writer = std::make_unique<ShmWriter>(spec(name, 2, 0, 4));
  writer->beat(monotonic_now_ns() - 3 * kNsPerSecond);  // as if its loop hung 3 s ago
  client::Subscriber reader(name);
  CHECK(reader.check_writer(kNsPerSecond) == FACECAP_WRITER_STALLED);  // it still holds the writer lock
  writer->beat(monotonic_now_ns());
  CHECK(reader.check_writer(kNsPerSecond) == FACECAP_OK);
  writer.reset();
  CHECK(reader.check_writer(kNsPerSecond) == FACECAP_ERR_WRITER_GONE);
}

TEST_CASE("a live writer's segment is refused, naming its pid") {
  const std::string name = unique_name("exclusive");
  ShmWriter live(spec(name));
  live.beat(monotonic_now_ns());
  try {
    ShmWriter second(spec(name));
    FAIL("a second writer was created over a live one");
  } catch (const Error& e) {
    CHECK_THAT(e.what(), Catch::Contains("already exists") && Catch::Contains(fmt::format("pid {} is writing", ::getpid())));
  }
  // However old its heartbeat, a writer that holds its lock keeps the name.
  live.beat(monotonic_now_ns() - 10 * kNsPerSecond);
  CHECK_THROWS_WITH(ShmWriter(spec(name)), Catch::Contains("stalled"));
}

namespace {

// A writer in a child process: it creates `name`, says so on a pipe, then beats every
// 10 ms until killed.
pid_t start_child_writer(const std::string& name) {
  int ready[2];
  REQUIRE(::pipe(ready) == 0);
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    ::close(ready[0]);
    try {
      ShmWriter writer(spec(name, 3, 0, 4));
      writer.publish(frame_with_pattern(1, 3, 0));
      const char ok = 1;
      if (::write(ready[1], &ok, 1) != 1) ::_exit(2);
      for (;;) {
        writer.beat(monotonic_now_ns());
        ::usleep(10'000);
      }
    } catch (...) {
      ::_exit(1);
    }
  }
  ::close(ready[1]);
  char ok = 0;
  const bool started = ::read(ready[0], &ok, 1) == 1 && ok == 1;
  ::close(ready[0]);
  REQUIRE(started);
  return child;
}

void kill_child(pid_t child) {
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
}

}  // namespace

TEST_CASE("a writer stopped for more than 2 s keeps its name against a second writer") {
  const std::string name = unique_name("stopped");
  const pid_t child = start_child_writer(name);
  client::Subscriber reader(name);
  REQUIRE(::kill(child, SIGSTOP) == 0);
  ::usleep(2'200'000);  // past the 2 s after which a heartbeat counted as dead before
  try {
    ShmWriter second(spec(name, 5, 0, 4));
    FAIL("a second writer took the name of a stopped one");
  } catch (const Error& e) {
    CHECK_THAT(e.what(), Catch::Contains(fmt::format("facecapd pid {} still holds it but is stalled", child)));
  }
  CHECK(reader.check_writer(kNsPerSecond) == FACECAP_WRITER_STALLED);
  CHECK(reader.shape_count() == 3);  // still the stopped writer's segment
  REQUIRE(::kill(child, SIGCONT) == 0);
  kill_child(child);
}

TEST_CASE("a killed writer's segment is taken over and its readers follow the new writer") {
  const std::string name = unique_name("killed");
  const pid_t child = start_child_writer(name);
  client::Subscriber reader(name);
  kill_child(child);  // the segment stays behind; the kernel dropped its lock
  CHECK(reader.check_writer(kNsPerSecond) == FACECAP_OK);  // the heartbeat alone still looks fresh
  ShmWriter replacement(spec(name, 6));
  CHECK(reader.check_writer(0) == FACECAP_RESTARTED);
  CHECK(reader.shape_count() == 6);
  CHECK(reader.writer_pid() == ::getpid());
}

TEST_CASE("a killed writer's segment is taken over even while a reader holds a read lock on it") {
  // A reader that locks what it reads (lockf(F_LOCK) or F_RDLCK on its read-only descriptor)
  // once kept a restarted facecapd from its name: the lock counted as a live writer's.
  const std::string name = unique_name("readlock");
  const pid_t child = start_child_writer(name);
  kill_child(child);
  const int fd = ::shm_open(("/" + name).c_str(), O_RDONLY, 0);
  REQUIRE(fd >= 0);
  struct flock read_lock = shm::whole_segment_lock(F_RDLCK);
  REQUIRE(::fcntl(fd, F_OFD_SETLK, &read_lock) == 0);
  CHECK_FALSE(shm::writer_lock_held(fd));  // a reader's lock is not a writer's
  client::Subscriber reader(name);
  CHECK(reader.check_writer(0) != FACECAP_WRITER_STALLED);
  ShmWriter replacement(spec(name, 6));  // threw "another writer is creating it" before
  CHECK(reader.check_writer(0) == FACECAP_RESTARTED);
  CHECK(reader.shape_count() == 6);
  replacement.beat(monotonic_now_ns());
  CHECK_THROWS_WITH(ShmWriter(spec(name)), Catch::Contains(fmt::format("pid {} is writing", ::getpid())));
  ::close(fd);
}

TEST_CASE("segments are created 0640 and mapped read-only by readers") {
  const std::string name = unique_name("mode");
  const mode_t old_umask = ::umask(0);  // the writer must not depend on the caller's umask
  ShmWriter writer(spec(name));
  ::umask(old_umask);
  struct stat st {};
  REQUIRE(::stat(("/dev/shm/" + name).c_str(), &st) == 0);
  CHECK((st.st_mode & 0777) == 0640);
  client::Subscriber reader(name);
  // The reader's mapping of this segment is read-only and shared ("r--s").
  std::ifstream maps("/proc/self/maps");
  std::string line;
  int reader_maps = 0, writable_reader_maps = 0;
  while (std::getline(maps, line)) {
    if (line.find("/dev/shm/" + name) == std::string::npos) continue;
    const std::string perms = line.substr(line.find(' ') + 1, 4);
    if (perms == "r--s") ++reader_maps;
    if (perms == "rw-s") ++writable_reader_maps;
  }
  CHECK(reader_maps == 1);
  CHECK(writable_reader_maps == 1);  // the writer's own mapping
}

TEST_CASE("the client refuses segments that are not facecap rings") {
  const std::string name = unique_name("garbage");
  const int fd = shm_open(("/" + name).c_str(), O_CREAT | O_EXCL | O_RDWR, 0600);
  REQUIRE(fd >= 0);
  REQUIRE(ftruncate(fd, 4096) == 0);
  const char junk[] = "not a facecap segment";
  REQUIRE(pwrite(fd, junk, sizeof junk, 0) == sizeof junk);
  close(fd);
  facecap_client* c = nullptr;
  CHECK(facecap_client_open(name.c_str(), &c) == FACECAP_ERR_LAYOUT);
  CHECK(c == nullptr);
  CHECK(facecap_client_open("facecap-test-no-such-segment", &c) == FACECAP_ERR_NOT_FOUND);
  CHECK(facecap_client_open("", &c) == FACECAP_ERR_ARGUMENT);
  try {
    ShmWriter writer(spec(name));
    FAIL("a writer took over a segment that is not a facecap ring");
  } catch (const Error& e) {
    CHECK_THAT(e.what(), Catch::Contains("not a facecap segment"));
  }
  shm_unlink(("/" + name).c_str());
}

TEST_CASE("shared-memory names are checked before anything is created") {
  CHECK_THROWS_WITH(outputs::shm_object_name("bad/name"), Catch::Contains("letters, digits"));
  CHECK_THROWS_WITH(outputs::shm_object_name(""), Catch::Contains("letters, digits"));
  CHECK(outputs::shm_object_name("facecap") == "/facecap");
  CHECK(outputs::shm_object_name("/facecap") == "/facecap");
}
