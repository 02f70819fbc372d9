#pragma once
// What the control API asks of the supervisor, and the bounded queue that carries it.
// The I/O thread parses a request into a Command and pushes it; the supervisor pops it
// on its own thread, does the work (long work on a worker thread) and calls `reply`
// once, from whichever thread finished. A full queue refuses the command (503) rather
// than growing. Nothing here is real-time code; the solve thread never sees it.
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <variant>

#include <nlohmann/json.hpp>

namespace facecap::control {

// An HTTP status and a JSON body.
struct Reply {
  int status = 200;
  nlohmann::json body;
  int retry_after_s = 0;  // > 0: sent as Retry-After (a 503 of a busy facecapd)
};
// {"error": what} with a 4xx/5xx status.
Reply error_reply(int status, std::string what);
using ReplyFn = std::function<void(Reply)>;

struct ListActors {};
// An actor's profile by name ("alice": alice.toml) or file name ("alice-cal.toml"), both
// in calibration.profiles_directory.
struct SelectActor {
  std::string name;
  std::string file;
};
// Capture `seconds` of the live source, calibrate on its most neutral stretch, swap the
// result in; save it as profile `save` when given.
struct Calibrate {
  double seconds = 3.0;
  std::string save;
  bool replace = false;  // an existing profile `save` is replaced, the old one kept as a backup
};
// A take and its slate; an empty take is the scene and shot's next take number.
struct StartRecording {
  std::string take, actor, scene, shot, notes;
  bool markers_only = false;  // raw markers only: a new actor with no profile yet
};
struct StopRecording {};
// The recordings in outputs.recording.directory.
struct ListRecordings {};
// Solved frames first, first + step, ... (at most count) of the recording `name` there.
struct ReadRecording {
  std::string name;
  uint64_t first = 0;
  uint64_t count = 1;
  uint64_t step = 1;
};

using Request =
    std::variant<ListActors, SelectActor, Calibrate, StartRecording, StopRecording, ListRecordings, ReadRecording>;

struct Command {
  Request request;
  ReplyFn reply;
};

// Reads of recordings (the replay page) are the one request many clients send at once.
bool is_recording_read(const Request& request) noexcept;

// Operator commands come first: reads of recordings may fill the queue only up to
// kSlotsKeptForCommands short of its capacity, and pop() hands out commands before reads.
class CommandQueue {
 public:
  static constexpr std::size_t kSlotsKeptForCommands = 8;
  explicit CommandQueue(std::size_t capacity) : capacity_(capacity) {}

  // False (the command not taken) when the queue is full for its kind. Any thread.
  bool push(Command command);
  // The oldest command other than a read of a recording, else the oldest read, if any. Any thread.
  std::optional<Command> pop();

 private:
  std::size_t capacity_;
  std::mutex mutex_;
  std::deque<Command> commands_;
};

}  // namespace facecap::control
