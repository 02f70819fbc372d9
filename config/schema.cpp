#include "config/schema.hpp"

#include <cmath>

#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/params.hpp"

namespace facecap::config {
namespace {

// The solver's own defaults: the schema's are these.
constexpr SolverParams kSolverDefaults{};

// The key path is the member path, so a key and the field it sets cannot disagree.
#define FACECAP_KEY(member) .path = #member, .field = +[](DaemonConfig& c) -> auto& { return c.member; }
// A choice key: the member is an enum, its names and descriptions come from `table`.
#define FACECAP_CHOICE_KEY(member, table) FACECAP_CHOICE_KEY_NAMED(#member, member, table)
// The same where the key's name is not the member's (solver.collisions, from before the
// solver's parameters were the configuration's).
#define FACECAP_CHOICE_KEY_NAMED(key, member, table)                                                   \
  .path = key, .field = ChoiceField {                                                                  \
    +[](const DaemonConfig& c) { return table.name(c.member); },                                       \
    +[](DaemonConfig& c, std::string_view name) {                                                      \
      const auto value = table.parse(name);                                                            \
      if (value) c.member = *value;                                                                    \
      return value.has_value();                                                                        \
    },                                                                                                 \
    +[] { return table.choices(); }                                                                    \
  }

// The keys of a marker-device section ([source.usb], [source.hid]): the same options, one
// struct (drivers::MarkerDeviceOptions), for either transport.
#define FACECAP_MARKER_DEVICE_KEYS(section, transport)                                                         \
  {FACECAP_KEY(section.vendor_id), .default_value = int64_t{0}, .min = 0, .max = 65535,                        \
   .description = "Vendor id of the " transport " marker device (TOML takes hex: 0x1209); 0 for any vendor."}, \
  {FACECAP_KEY(section.product_id), .default_value = int64_t{0}, .min = 0, .max = 65535,                       \
   .description = "Product id of the device; 0 for any product."},                                            \
  {FACECAP_KEY(section.serial), .default_value = std::string(),                                                \
   .description = "Serial number of the device, to pick one of several alike; empty for any."},              \
  {FACECAP_KEY(section.rate_hz), .default_value = 0.0, .unit = "Hz", .min = 0, .max = 2000,                    \
   .description = "Frame rate to ask the device for; 0 keeps the rate it states in its info block."},          \
  {FACECAP_KEY(section.wait_for_device), .default_value = false,                                              \
   .description = "When no such device is plugged in at start, wait for it (STATUS says so, READY follows "   \
                  "the first frame) instead of refusing to start. A device that goes away while running is "   \
                  "always waited for and reopened."}

const std::vector<KeySpec>& schema_rows() {
  static const std::vector<KeySpec> rows = {
      {FACECAP_KEY(version), .default_value = int64_t{1}, .min = 1, .max = 1,
       .description = "Version of this file's format; this facecapd reads version 1."},

      {FACECAP_CHOICE_KEY(source.driver, drivers::kDriverIds), .default_value = std::string("sim"),
       .description = "The driver that delivers marker frames."},

      {FACECAP_KEY(source.sim.rate_hz), .default_value = 120.0, .unit = "Hz", .min = 1, .max = 2000,
       .description = "Frames per second the simulated capture system delivers."},
      {FACECAP_KEY(source.sim.motion), .default_value = std::string("builtin"),
       .names_input_file = true,
       .description = "The performance: \"builtin\" (smooth curves over jaw, blinks, smiles, brows and lips) or the "
                      "path of a Live Link Face CSV whose ARKit weights drive the rig's shapes of the same names "
                      "(looped)."},
      {FACECAP_KEY(source.sim.noise_mm), .default_value = 0.1, .unit = "mm", .min = 0, .max = 10,
       .description = "Gaussian noise added to every marker coordinate (standard deviation)."},
      {FACECAP_KEY(source.sim.dropout_probability), .default_value = 0.005, .min = 0, .max = 1,
       .description = "Chance that a marker is missing from a frame, as if occluded."},
      {FACECAP_KEY(source.sim.head_motion_degrees), .default_value = 4.0, .unit = "degrees", .min = 0, .max = 45,
       .description = "Amplitude of the head's sway (yaw; pitch and roll are smaller)."},
      {FACECAP_KEY(source.sim.head_motion_mm), .default_value = 8.0, .unit = "mm", .min = 0, .max = 200,
       .description = "Amplitude of the head's drift."},
      {FACECAP_KEY(source.sim.seed), .default_value = int64_t{1}, .min = 0, .max = 4294967295.0,
       .description = "Seed of the noise and dropouts: the same seed gives the same frames."},

      {FACECAP_KEY(source.replay.file), .default_value = std::string(),
       .names_input_file = true,
       .description = "Take to play: .c3d, .trc, .fcrec (a facecapd recording), or a .pcap/.pcapng capture of "
                      "NatNet traffic (its markers chosen by source.natnet.marker_set and unlabelled_markers, played "
                      "at their recorded timing). Required when source.driver is \"replay\"."},
      {FACECAP_KEY(source.replay.speed), .default_value = 1.0, .min = 0, .max = 100,
       .description = "Playback speed relative to real time; 0 hands frames as fast as the loop takes them."},
      {FACECAP_KEY(source.replay.loop), .default_value = false,
       .description = "Start again at the window's beginning after its end; otherwise facecapd stops cleanly when "
                      "the take ends."},
      {FACECAP_KEY(source.replay.start_s), .default_value = 0.0, .unit = "s", .min = 0, .max = 1e7,
       .description = "Start of the window into the take, in seconds after its first frame."},
      {FACECAP_KEY(source.replay.end_s), .default_value = 0.0, .unit = "s", .min = 0, .max = 1e7,
       .description = "End of the window, in seconds after the take's first frame; 0 plays to the end."},
      {FACECAP_KEY(source.replay.source_timestamps), .default_value = true,
       .description = "Pace frames by the file's own timestamps (gaps stay gaps); false paces them at the take's "
                      "nominal rate."},
      {FACECAP_CHOICE_KEY(source.replay.units, drivers::kTakeUnits), .default_value = std::string("stated"),
       .description = "Units the take's values are read in, for a take that states them wrongly or not at all (as "
                      "`facecap solve --units`). facecapd refuses a take whose face is not about the calibrated "
                      "one's size in these units, and says which units it looks like."},

      FACECAP_MARKER_DEVICE_KEYS(source.usb, "USB"),
      FACECAP_MARKER_DEVICE_KEYS(source.hid, "HID"),

      {FACECAP_KEY(source.v4l2.calibration), .default_value = std::string(), .names_input_file = true,
       .description = "The cameras' calibration: an OpenCV-style YAML file with each camera's matrix, distortion "
                      "coefficients, rotation and translation (docs/cameras.md). Required when source.driver is "
                      "\"v4l2\"."},
      {FACECAP_KEY(source.v4l2.devices), .default_value = std::string(),
       .description = "The V4L2 device of each calibrated camera, in the calibration's order, comma-separated "
                      "(\"/dev/v4l/by-id/usb-...-video-index0, ...\": by-id paths survive replugging)."},
      {FACECAP_CHOICE_KEY(source.v4l2.pixel_format, drivers::kPixelFormats), .default_value = std::string("auto"),
       .description = "The format asked of the cameras."},
      {FACECAP_KEY(source.v4l2.frame_rate_hz), .default_value = 0.0, .unit = "Hz", .min = 0, .max = 1000,
       .description = "Frame rate asked of the cameras; 0 keeps theirs."},
      {FACECAP_KEY(source.v4l2.threshold), .default_value = int64_t{80}, .min = 1, .max = 254,
       .description = "Grey level a marker's pixels exceed; the markers' own glow and the background's decide it "
                      "(docs/cameras.md)."},
      {FACECAP_KEY(source.v4l2.min_blob_area_px), .default_value = int64_t{4}, .unit = "pixels", .min = 1,
       .max = 100000, .description = "Smaller blobs are noise, not markers."},
      {FACECAP_KEY(source.v4l2.max_blob_area_px), .default_value = int64_t{400}, .unit = "pixels", .min = 1,
       .max = 100000, .description = "Larger blobs are reflections or lamps, not markers."},
      {FACECAP_KEY(source.v4l2.min_roundness), .default_value = 0.6, .min = 0, .max = 1,
       .description = "Least minor/major axis ratio of a marker's blob: streaks and merged markers fall below it."},
      {FACECAP_KEY(source.v4l2.epipolar_tolerance_px), .default_value = 1.0, .unit = "pixels", .min = 0.05, .max = 20,
       .description = "How far two cameras' blobs may lie from each other's epipolar lines and still be one marker; "
                      "points must reproject within 1.5 times this."},
      {FACECAP_KEY(source.v4l2.sync_tolerance_ms), .default_value = 2.0, .unit = "ms", .min = 0, .max = 1000,
       .description = "Frames of different cameras at most this far apart in time make one set (hardware-synced "
                      "cameras: well under a period; free-running ones: half a period)."},
      {FACECAP_KEY(source.v4l2.max_points), .default_value = int64_t{64}, .min = 1, .max = 1024,
       .description = "3D points a frame carries at most (its unlabelled slots); more are dropped and counted."},
      {FACECAP_KEY(source.natnet.server_address), .default_value = std::string(),
       .description = "IPv4 address of the NatNet server (the Motive PC, or `facecap natnet-serve`) that commands "
                      "go to. Empty: find it by broadcasting NAT_DISCOVERY to source.natnet.discovery_address and "
                      "take the first server that answers."},
      {FACECAP_KEY(source.natnet.discovery_address), .default_value = std::string("255.255.255.255"),
       .description = "Where the discovery broadcast goes when no server_address is given (the subnet's broadcast "
                      "address, such as 192.168.0.255, keeps it on one network)."},
      {FACECAP_KEY(source.natnet.command_port), .default_value = int64_t{1510}, .min = 1, .max = 65535,
       .description = "The server's command port: NAT_CONNECT, model definitions, requests, keep-alives."},
      {FACECAP_KEY(source.natnet.data_port), .default_value = int64_t{1511}, .min = 1, .max = 65535,
       .description = "Port frames arrive on when multicast, or unicast from a 3.x-style server (a 4.x unicast "
                      "server sends them to the command socket instead; both are read). Several facecapd on one host "
                      "share it."},
      {FACECAP_KEY(source.natnet.local_interface), .default_value = std::string(),
       .description = "The interface facing the capture network, by IPv4 address or name (\"eth1\", \"lo\"): "
                      "commands are sent from it and the multicast group is joined on it. Empty: the system's choice."},
      {FACECAP_CHOICE_KEY(source.natnet.transport, drivers::kNatNetTransports), .default_value = std::string("auto"),
       .description = "How frames come: as the server says, or insist on one (a server that says otherwise is an "
                      "error at start)."},
      {FACECAP_KEY(source.natnet.multicast_group), .default_value = std::string(),
       .description = "Multicast group to join; empty: the group the server announces (Motive's default is "
                      "239.255.42.99)."},
      {FACECAP_KEY(source.natnet.marker_set), .default_value = std::string(),
       .description = "The marker set whose markers are solved (the actor's face, by its name in Motive): its "
                      "labelled markers get Motive's marker names, and only they are taken from a stream that "
                      "carries several actors. Empty: no labelled markers, only unlabelled points "
                      "(source.natnet.unlabelled_markers). Also chooses the markers of a capture replayed with "
                      "source.driver = \"replay\"."},
      {FACECAP_KEY(source.natnet.unlabelled_markers), .default_value = int64_t{0}, .unit = "markers", .min = 0,
       .max = 1024,
       .description = "Slots for unlabelled points after the marker set's (points Motive has not labelled; without a "
                      "marker set, every point seen); more in a frame are dropped and counted. Without a marker set "
                      "the points go to the labeller (calibration.label_markers is turned on). Also applies to "
                      "replayed captures."},
      {FACECAP_CHOICE_KEY(source.natnet.bitstream, drivers::kNatNetBitstreams), .default_value = std::string("server"),
       .description = "The frame layout: the server's NatNet version, or one asked for (a 4.x server streaming "
                      "unicast is asked to send it; otherwise frames are only read as it)."},
      {FACECAP_KEY(source.natnet.connect_timeout_s), .default_value = 5.0, .unit = "s", .min = 0.1, .max = 600,
       .description = "At start, how long to wait for the server's NAT_SERVERINFO and model definitions; facecapd "
                      "does not start without them, since the marker names come from them."},
      {FACECAP_KEY(source.natnet.silence_timeout_s), .default_value = 1.0, .unit = "s", .min = 0.05, .max = 600,
       .description = "No frame for this long: STATUS says so (\"no frames from 10.0.0.5 for 3.2 s\") and the driver "
                      "reconnects every second until frames come again, the daemon running throughout."},
      {FACECAP_KEY(source.natnet.timecode_rate_hz), .default_value = int64_t{30}, .unit = "Hz", .min = 1, .max = 1000,
       .description = "Frame rate of the SMPTE timecode the server stamps (its timecode generator's); frames do not "
                      "say it."},

      {FACECAP_KEY(rig.path), .default_value = std::string("builtin"),
       .names_input_file = true,
       .description = "The rig to solve: \"builtin\" (the synthetic face), an OBJ directory (ICT FaceKit layout or "
                      "with rig.toml), a .toml manifest, a .gltf/.glb or an .fbx file."},
      {FACECAP_KEY(rig.cache), .default_value = true,
       .description = "Keep a binary cache of parsed rigs ($FACECAP_CACHE_DIR, else ~/.cache/facecap) so that "
                      "restarts load the rig in milliseconds."},

      {FACECAP_KEY(calibration.file), .default_value = std::string(),
       .reload = Reload::kRebuild, .names_input_file = true,
       .description = "Marker calibration (TOML, see docs/config.md): a profile written by `facecap calibrate`, or a "
                      "hand-written file naming which rig point each marker sits on, the head markers, and the "
                      "transform from marker space to rig space. Empty: the default marker set, in rig space, which "
                      "the sim produces."},
      {FACECAP_KEY(calibration.profiles_directory), .default_value = std::string("profiles"),
       .description = "Where actor profiles live (relative to the working directory; the systemd unit runs in "
                      "/var/lib/facecap): the control API lists them (GET /actors), loads one by name (POST /actor) "
                      "and saves a calibration made on the box there (POST /calibrate with \"save\")."},
      {FACECAP_KEY(calibration.face_markers), .default_value = int64_t{48}, .min = 3, .max = 1000,
       .description = "Face markers of the default marker set: first where they observe the rig's shapes (lids, brows, mouth), the rest spread evenly (labels M000, M001, ...)."},
      {FACECAP_KEY(calibration.head_markers), .default_value = int64_t{4}, .min = 0, .max = 16,
       .description = "Markers on a rigid headband in the default marker set (labels H0, H1, ...); 0 for none, else "
                      "at least 3."},
      {FACECAP_KEY(calibration.stabilise_head), .default_value = true, .reload = Reload::kRebuild,
       .description = "Fit the head's rigid motion to the head markers every frame and solve the face in head space "
                      "(needs 3 head markers present; otherwise the last pose is held)."},
      {FACECAP_KEY(calibration.neutral_min_presence), .default_value = 0.8, .min = 0.05, .max = 1.0,
       .description = "Calibration on the box (POST /calibrate): the neutral stretch is the stillest one where each "
                      "marker is present in at least this fraction of the frames; a marker's neutral position is the "
                      "robust mean of its samples there. A marker below it in every stretch is named in the refusal."},
      {FACECAP_KEY(calibration.max_marker_speed_mm_s), .default_value = 1000.0, .unit = "mm/s", .min = 0, .max = 1e6,
       .reload = Reload::kRebuild,
       .description = "A marker whose target (rig space, head stabilised) moved faster than this since it was last "
                      "accepted is left out of that frame and the frame is flagged implausible_marker: one glitch "
                      "costs one frame. The fastest marker in the real takes tried (AnimFace, 60 Hz) moved 229 mm/s; "
                      "a 10 cm jump in one frame is 6000 mm/s at 60 Hz. 0 turns the check off."},

      {FACECAP_KEY(calibration.marker_consistency_mm), .default_value = 0.0, .unit = "rig mm", .min = 0, .max = 1000,
       .reload = Reload::kRebuild,
       .description = "Each face marker's target is compared with its neighbours' (against where the rig puts them "
                      "under the last frame's weights); one further than this from their median is left out of the "
                      "frame, and two that trade places are swapped back; such a frame is flagged "
                      "inconsistent_marker. Catches label swaps that glide too slowly for max_marker_speed_mm_s. 0 "
                      "(the default: on clean takes it also leaves out markers that truly moved unlike their "
                      "neighbours, docs/alignment.md \"Label swaps\") turns it off; 10 is the suggested value."},
      {FACECAP_KEY(calibration.label_markers), .default_value = false, .reload = Reload::kRebuild,
       .description = "Label every frame afresh: its points go to the labeller, which matches them to the "
                      "calibration's markers (tracking them from frame to frame, re-acquiring the set from the "
                      "calibration's neutral shape when it loses it), so that a face is solved from an unlabelled "
                      "point cloud. The labels a source gives are ignored. Turned on by itself for a source that "
                      "delivers only unlabelled points (v4l2, natnet without a marker_set, a replay of either)."},

      {FACECAP_CHOICE_KEY(solver.method, kSolverMethods), .default_value = std::string("nonlinear"),
       .reload = Reload::kRebuild,
       .description = "The per-frame face solver."},
      {FACECAP_KEY(solver.alpha), .default_value = kSolverDefaults.alpha, .min = 0, .max = 1000, .reload = Reload::kRebuild,
       .description = "Temporal smoothing of the weights: alpha |w - w_prev|^2 in Eq. 2."},
      {FACECAP_KEY(solver.mu), .default_value = kSolverDefaults.mu, .min = 0, .max = 1000, .reload = Reload::kRebuild,
       .description = "Regularisation of the weights' size: mu |w|^2 in Eq. 2."},
      {FACECAP_KEY(solver.beta), .default_value = kSolverDefaults.beta, .min = 0.001, .max = 1e6, .reload = Reload::kRebuild,
       .description = "How strongly markers pin the mesh in Eq. 5."},
      {FACECAP_KEY(solver.weight_refinements), .default_value = int64_t{kSolverDefaults.weight_refinements}, .min = -1, .max = 10,
       .reload = Reload::kRebuild,
       .description = "Gauss-Newton refinements of the weights along the paths rotations move markers (nonlinear "
                      "solver); 0 gives the paper's linear fit. -1: the rig's choice, 2 for a hinged rig (the built-in "
                      "face, or a rig manifest's hinged = true) and 0 for others (on an artist's rig they re-mix its "
                      "own poses)."},
      {FACECAP_CHOICE_KEY_NAMED("solver.collisions", solver.collision_region, kCollisionRegions),
       .default_value = std::string(kCollisionRegions.name(kSolverDefaults.collision_region)),
       .reload = Reload::kRebuild,
       .description = "Which triangles the collision stage checks for pairs closer than collision_epsilon."},
      {FACECAP_KEY(solver.collision_epsilon), .default_value = kSolverDefaults.collision_epsilon, .unit = "rig units", .min = 0, .max = 10,
       .reload = Reload::kRebuild,
       .description = "Triangle pairs closer than this are held apart at their linear-blend positions."},
      {FACECAP_KEY(solver.collision_max_pins), .default_value = int64_t{kSolverDefaults.collision_max_pins}, .unit = "vertices", .min = 0, .max = 1024,
       .reload = Reload::kRebuild,
       .description = "Vertices the collision stage pins per frame at most, which bounds its cost (64 pins take "
                      "about 0.15 ms on a 6,706-vertex face); a pose that needs more keeps some crossings."},
      {FACECAP_KEY(solver.collision_skin_mm), .default_value = kSolverDefaults.collision_skin_mm, .unit = "mm", .min = 0, .max = 100,
       .reload = Reload::kRebuild,
       .description = "The collision stage finds the lip triangles whose boxes come near each other only when a lip "
                      "vertex has moved farther than this since it last looked, and tests those pairs in between; "
                      "the pairs found do not depend on it, only the stage's time. 0 looks every frame."},
      {FACECAP_KEY(solver.boundary_hold), .default_value = kSolverDefaults.boundary_hold, .unit = "times beta", .min = -1, .max = 100,
       .reload = Reload::kRebuild,
       .description = "How strongly the mesh's outer edge is held to the rig's linear blend of the weights (the eyes' "
                      "and mouth's openings stay free); 0 leaves it free, so that a pinned solve can carry the "
                      "markers' motion out to it. -1: the rig's choice, 0.003, and 0 for a hinged rig (the built-in "
                      "face, whose jaw swings its edge)."},
      {FACECAP_KEY(solver.fold_max_pins), .default_value = int64_t{kSolverDefaults.fold_max_pins}, .unit = "vertices", .min = 0, .max = 1024,
       .reload = Reload::kRebuild,
       .description = "Vertices of triangles the non-linear solve folded (flipped, or creased past fold_crease_degrees, "
                      "against the rig's linear blend of the same weights) pinned to that blend per frame at most; 0 "
                      "only measures. A frame still folded is flagged folded."},
      {FACECAP_KEY(solver.fold_crease_degrees), .default_value = kSolverDefaults.fold_crease_degrees, .unit = "degrees", .min = 10, .max = 180,
       .reload = Reload::kRebuild,
       .description = "A crease counts as a fold when the normals across an edge turn this much more than in the "
                      "rig's linear blend of the same weights."},
      {FACECAP_KEY(solver.active_weight), .default_value = kSolverDefaults.active_weight, .min = 0, .max = 0.1, .reload = Reload::kRebuild,
       .description = "Weights below this are left out of the non-linear blend (Eq. 4), for speed."},
      {FACECAP_KEY(solver.negligible_displacement_mm), .default_value = kSolverDefaults.negligible_displacement_mm, .unit = "mm",
       .min = 0, .max = 1, .reload = Reload::kRebuild,
       .description = "A shape whose weight moves no vertex by more than this (weight times the shape's largest "
                      "displacement) is left out of the blends for that frame, for speed; its weight is still sent. "
                      "0 blends every shape above active_weight."},
      {FACECAP_CHOICE_KEY(solver.kernels, kKernelPaths), .default_value = std::string(kKernelPaths.name(kSolverDefaults.kernels)),
       .reload = Reload::kRebuild,
       .description = "Which compiled per-frame kernels solve: auto takes the widest instruction set this CPU runs "
                      "(facecapd logs it, /status shows it); a path the CPU lacks is refused at start."},

      {FACECAP_CHOICE_KEY(filter.mode, kFilterModes), .default_value = std::string("live"), .reload = Reload::kRebuild,
       .description = "When to filter the marker targets in time (the One Euro filter, after head stabilisation, so "
                      "that only the face's own motion is filtered): live sources are filtered, offline solves are "
                      "not unless asked (facecap solve --set filter.mode=on)."},
      {FACECAP_KEY(filter.min_cutoff_hz), .default_value = 1.0, .unit = "Hz", .min = 0.01, .max = 1000,
       .reload = Reload::kRebuild,
       .description = "The filter's cutoff while the face is still. Lower: less jitter at rest, more lag in slow "
                      "motion (about 1 / (2 pi min_cutoff_hz) seconds)."},
      {FACECAP_KEY(filter.beta), .default_value = 0.5, .unit = "Hz per mm/s", .min = 0, .max = 1000,
       .reload = Reload::kRebuild,
       .description = "How fast the cutoff rises with a marker's speed (rig space, in the rig's mm). Higher: less lag "
                      "in fast motion, more noise let through while moving; 0 is a fixed low-pass at min_cutoff_hz."},
      {FACECAP_KEY(filter.d_cutoff_hz), .default_value = 1.0, .unit = "Hz", .min = 0.01, .max = 1000,
       .reload = Reload::kRebuild,
       .description = "The cutoff of the speed estimate beta multiplies (higher: the cutoff follows speed sooner and "
                      "noisier)."},
      {FACECAP_KEY(filter.weights), .default_value = false, .reload = Reload::kRebuild,
       .description = "Also filter the solved weights sent out (not the mesh, which the filtered targets already "
                      "smooth), with min_cutoff_hz, d_cutoff_hz and weights_beta, whenever the targets are filtered."},
      {FACECAP_KEY(filter.weights_beta), .default_value = 1.0, .unit = "Hz per weight/s", .min = 0, .max = 1000,
       .reload = Reload::kRebuild,
       .description = "How fast the weights' cutoff rises with their speed (a weight going 0 to 1 in a second: 1)."},

      {FACECAP_KEY(loop.rate_hz), .default_value = 120.0, .unit = "Hz", .min = 1, .max = 2000,
       .description = "Ticks per second of the fixed-rate solve loop."},
      {FACECAP_CHOICE_KEY(loop.mode, kLoopModes), .default_value = std::string("fixed"),
       .description = "How the loop takes frames."},
      {FACECAP_KEY(loop.phase_margin_us), .default_value = int64_t{300}, .unit = "us", .min = 0, .max = 100000,
       .description = "With a source on its own clock (sim, live devices) the loop shifts its ticks to fall this "
                      "long after frames arrive, so frames wait as little as possible, and up to a quarter period "
                      "longer while frames arrive late (docs/daemon.md, the solve loop); 0 keeps the ticks fixed."},
      {FACECAP_KEY(loop.prefetch_lead_us), .default_value = int64_t{800}, .unit = "us", .min = 0, .max = 100000,
       .description = "In fixed mode the loop wakes this long before each tick to prefetch the solver's largest "
                      "tables (the blend's terms) into the cache, so that a solve after a sleep does not start from "
                      "main memory (ICT FaceKit at 240 Hz: the blend stage 10% faster for 6% more CPU); 0 turns it off."},
      {FACECAP_KEY(loop.realtime), .default_value = true,
       .description = "Try SCHED_FIFO for the solve thread, and two priorities below it for the I/O "
                      "thread that sends the network outputs and serves the control API (needs CAP_SYS_NICE or "
                      "RLIMIT_RTPRIO); a failure is reported, never fatal."},
      {FACECAP_KEY(loop.priority), .default_value = int64_t{0}, .min = 0, .max = 99,
       .description = "SCHED_FIFO priority; 0 picks the middle of the range. Clamped to RLIMIT_RTPRIO."},
      {FACECAP_KEY(loop.lock_memory), .default_value = false,
       .description = "mlockall() so that the solve thread never waits for a page fault (needs CAP_IPC_LOCK or a "
                      "large RLIMIT_MEMLOCK)."},
      {FACECAP_KEY(loop.cpu_affinity), .default_value = std::vector<int64_t>{}, .unit = "CPU numbers", .min = 0,
       .max = 1023, .description = "CPUs the solve thread may run on; empty for any."},

      {FACECAP_KEY(outputs.shm.enabled), .default_value = true,
       .description = "Publish solved frames in a shared-memory ring (docs/shm-format.md)."},
      {FACECAP_KEY(outputs.shm.name), .default_value = std::string("facecap"),
       .description = "Name of the ring (/dev/shm/<name>): letters, digits, '-', '_', '.'. Readers open it by this "
                      "name."},
      {FACECAP_KEY(outputs.shm.slots), .default_value = int64_t{8}, .min = 2, .max = 1024,
       .description = "Frames the ring holds: a reader can fall this far behind before it loses frames."},
      {FACECAP_KEY(outputs.shm.vertices), .default_value = true,
       .description = "Publish the solved vertex positions as well as the weights."},

      {FACECAP_KEY(outputs.recording.enabled), .default_value = false,
       .description = "Record raw marker frames and solved frames while running."},
      {FACECAP_KEY(outputs.recording.directory), .default_value = std::string("recordings"),
       .description = "Where recordings go, one facecapd-<date>-<time>.fcrec per run (relative to the working "
                      "directory; the systemd unit runs in /var/lib/facecap)."},
      {FACECAP_KEY(outputs.recording.markers), .default_value = true, .description = "Record the raw marker frames."},
      {FACECAP_KEY(outputs.recording.solved), .default_value = true, .description = "Record the solved frames."},
      {FACECAP_KEY(outputs.recording.vertices), .default_value = false,
       .description = "Record the solved vertex positions with each solved frame (large: 80 KB a frame for a "
                      "6,706-vertex face); without them, `facecap solve` of the recording reproduces them."},
      {FACECAP_KEY(outputs.recording.queue_frames), .default_value = int64_t{512}, .unit = "frames", .min = 8, .max = 65536,
       .description = "How far the recorder may fall behind before frames are dropped (and counted) rather than "
                      "slowing the loop."},

      {FACECAP_KEY(outputs.udp.enabled), .default_value = false,
       .description = "Send every solved frame as facecap's own UDP stream (docs/udp-stream.md), which the client "
                      "library and `facecap subscribe --udp` receive."},
      {FACECAP_KEY(outputs.udp.address), .default_value = std::string("127.0.0.1"),
       .description = "Where to send: a unicast address (this machine by default) or a multicast group "
                      "(224.0.0.0 to 239.255.255.255, ff00::/8) for any number of receivers. A numeric IPv4 or IPv6 "
                      "address."},
      {FACECAP_KEY(outputs.udp.port), .default_value = int64_t{39540}, .min = 1, .max = 65535,
       .description = "UDP port of the receivers."},
      {FACECAP_KEY(outputs.udp.max_rate_hz), .default_value = 0.0, .unit = "Hz", .min = 0, .max = 2000,
       .description = "Send at most this many frames a second (every 2nd, 3rd, ... solved frame); 0 sends every one."},
      {FACECAP_KEY(outputs.udp.vertices), .default_value = false,
       .description = "Send the solved vertex positions as well as the weights (a 6,706-vertex face adds 80 KB, 59 "
                      "datagrams, a frame: 19 MB/s at 240 Hz)."},
      {FACECAP_KEY(outputs.udp.multicast_ttl), .default_value = int64_t{1}, .min = 0, .max = 255,
       .description = "Hops a multicast datagram may take: 1 stays on the local network."},
      {FACECAP_KEY(outputs.udp.multicast_interface), .default_value = std::string(),
       .description = "Network interface to send multicast on, by name (\"eth0\"); empty for the system's choice."},

      {FACECAP_KEY(outputs.vmc.enabled), .default_value = false,
       .description = "Send blendshape weights as OSC with the VMC protocol (docs/outputs.md): per frame one bundle "
                      "of /VMC/Ext/Blend/Val for each shape, then /VMC/Ext/Blend/Apply."},
      {FACECAP_KEY(outputs.vmc.address), .default_value = std::string("127.0.0.1"),
       .description = "Address of the VMC receiver (the \"marionette\"): numeric IPv4 or IPv6."},
      {FACECAP_KEY(outputs.vmc.port), .default_value = int64_t{39539}, .min = 1, .max = 65535,
       .description = "UDP port of the receiver; 39539 is the VMC protocol's."},
      {FACECAP_KEY(outputs.vmc.max_rate_hz), .default_value = 0.0, .unit = "Hz", .min = 0, .max = 2000,
       .description = "Send at most this many frames a second (every 2nd, 3rd, ... solved frame); 0 sends every one."},
      {FACECAP_CHOICE_KEY(outputs.vmc.names, kVmcNames), .default_value = std::string("arkit"),
       .description = "What the shapes are called in /VMC/Ext/Blend/Val."},
      {FACECAP_KEY(outputs.vmc.map_file), .default_value = std::string(), .names_input_file = true,
       .description = "With names = \"map\": a TOML file whose [names] table maps rig shape names to the names "
                      "to send (jawOpen = \"A\"); shapes it leaves out are not sent."},
      {FACECAP_KEY(outputs.vmc.root_pose), .default_value = false,
       .description = "Also send the solved head pose as /VMC/Ext/Root/Pos (Unity's left-handed axes)."},
      {FACECAP_KEY(outputs.vmc.root_scale), .default_value = 0.01, .unit = "m per rig unit", .min = 0, .max = 1000,
       .description = "Metres per rig unit of the head position in /VMC/Ext/Root/Pos (0.01 for a rig in "
                      "centimetres such as ICT FaceKit)."},

      {FACECAP_KEY(outputs.livelink.enabled), .default_value = false,
       .description = "Send Unreal Live Link Face packets (version 6, as the Live Link Face iPhone app does; "
                      "docs/outputs.md): the 52 ARKit weights and the head's yaw, pitch and roll."},
      {FACECAP_KEY(outputs.livelink.address), .default_value = std::string("127.0.0.1"),
       .description = "Address of the machine running Unreal (or another Live Link Face receiver): numeric IPv4 or "
                      "IPv6."},
      {FACECAP_KEY(outputs.livelink.port), .default_value = int64_t{11111}, .min = 1, .max = 65535,
       .description = "UDP port Unreal's Live Link Face source listens on."},
      {FACECAP_KEY(outputs.livelink.max_rate_hz), .default_value = 0.0, .unit = "Hz", .min = 0, .max = 2000,
       .description = "Send at most this many frames a second (every 2nd, 3rd, ... solved frame); 0 sends every one."},
      {FACECAP_KEY(outputs.livelink.subject_name), .default_value = std::string("facecap"),
       .description = "The Live Link subject the face appears as in Unreal."},
      {FACECAP_KEY(outputs.livelink.device_id), .default_value = std::string(),
       .description = "Device id sent with every packet; empty: a UUID made from this machine's /etc/machine-id and "
                      "the subject name, the same at every start."},

      {FACECAP_KEY(control.status_interval_s), .default_value = 1.0, .unit = "s", .min = 0.1, .max = 60,
       .reload = Reload::kLive,
       .description = "How often facecapd updates systemd's STATUS= line (rate, overruns, latency)."},
      {FACECAP_KEY(control.run_seconds), .default_value = 0.0, .unit = "s", .min = 0, .max = 1e7,
       .description = "Stop cleanly after this long (benchmarks, tests); 0 runs until stopped."},

      {FACECAP_KEY(control.http.enabled), .default_value = false,
       .description = "Serve the control API (docs/control-api.md): status, Prometheus metrics, actors, calibration "
                      "and takes over HTTP/JSON, and a WebSocket stream of solved frames; `facecap ctl` drives it."},
      {FACECAP_KEY(control.http.address), .default_value = std::string("127.0.0.1"),
       .description = "IP address the control API listens on (an address, not a host name). Any address but "
                      "loopback (127.0.0.0/8, ::1) needs control.http.token_file."},
      {FACECAP_KEY(control.http.port), .default_value = int64_t{8765}, .min = 0, .max = 65535,
       .description = "TCP port of the control API; 0 picks a free one (logged)."},
      {FACECAP_KEY(control.http.token_file), .default_value = std::string(), .names_input_file = true,
       .description = "File holding the operator's token: API clients send it as `Authorization: Bearer <token>`, the "
                      "dashboard's login page exchanges it for a session cookie. Required when the address is not "
                      "loopback; refused when group or others may read it (chmod 600). Empty: no token, every local "
                      "client is the operator."},
      {FACECAP_KEY(control.http.viewer_token_file), .default_value = std::string(), .names_input_file = true,
       .description = "File holding a viewer's token (needs control.http.token_file): read-only access, status, "
                      "metrics, recordings and the stream but no commands. Refused when group or others may read it."},
      {FACECAP_KEY(control.http.allowed_hosts), .default_value = std::string(),
       .description = "Further host names the box is reached by, comma-separated (`stage-box.local, facecap.lan`): a "
                      "request's Host must be the address listened on, `localhost` on loopback, or one of these "
                      "(keeps DNS rebinding out)."},
      {FACECAP_KEY(control.http.allowed_origins), .default_value = std::string(),
       .description = "Further web origins whose pages may send commands and open the stream, comma-separated "
                      "(`http://tablet-ui.lan:8080`); the dashboard served by facecapd itself needs no entry."},
      {FACECAP_KEY(control.http.session_max_age_s), .default_value = int64_t{43200}, .unit = "s", .min = 60,
       .max = 30 * 86400,
       .description = "How long a dashboard login lasts (the session cookie's Max-Age)."},
      {FACECAP_KEY(control.http.max_connections), .default_value = int64_t{64}, .min = 16, .max = 4096,
       .description = "Most connections the control API holds at once, HTTP and WebSocket together; 8 of them are "
                      "kept for clients that have sent an authenticated request, and the oldest connection that has "
                      "not yet makes way for a new one (docs/control-api.md, \"Limits\")."},
      {FACECAP_KEY(control.http.max_connections_per_address), .default_value = int64_t{16}, .min = 1, .max = 4096,
       .description = "Most connections one client address may hold before it has sent an authenticated request; "
                      "beyond it, that address's oldest such connection makes way for its new one."},
      {FACECAP_KEY(control.http.max_stream_clients), .default_value = int64_t{16}, .min = 0, .max = 4096,
       .description = "Most WebSocket /stream clients at once (at most control.http.max_connections - 8); more are "
                      "answered 503."},
      {FACECAP_KEY(control.http.tls), .default_value = false,
       .description = "Serve the control API and the dashboard over TLS only (https://, wss://): the token, the "
                      "session cookie (then Secure) and the stream are encrypted on the stage network. The "
                      "certificate and key are control.http.tls_certificate and tls_key, made on first start when "
                      "neither exists (docs/control-api.md#tls)."},
      {FACECAP_KEY(control.http.tls_certificate), .default_value = std::string("tls/facecapd.crt"),
       .description = "The control API's TLS certificate (PEM, the chain after it). When neither it nor "
                      "control.http.tls_key exists, facecapd makes a self-signed one naming control.http.address (every "
                      "interface's address for 0.0.0.0 or ::), localhost and control.http.allowed_hosts, valid 825 days, "
                      "and logs its SHA-256 fingerprint. Relative to the working directory (/var/lib/facecap under "
                      "systemd)."},
      {FACECAP_KEY(control.http.tls_key), .default_value = std::string("tls/facecapd.key"),
       .description = "The private key of control.http.tls_certificate (PEM, no passphrase); refused when group or "
                      "others may read it (chmod 600)."},
      {FACECAP_KEY(control.http.dashboard_dir), .default_value = std::string(),
       .description = "Directory of the operator dashboard's built files, served at / (docs/dashboard.md). Empty: "
                      "the dashboard built with this facecapd (in its build tree) or installed with it "
                      "(share/facecap/dashboard)."},

      {FACECAP_KEY(quality.markers_used_degraded), .default_value = 0.9, .min = 0, .max = 1, .reload = Reload::kLive,
       .description = "The capture is degraded when the solve uses fewer than this fraction of the calibration's "
                      "face markers (on average over a status window)."},
      {FACECAP_KEY(quality.markers_used_bad), .default_value = 0.6, .min = 0, .max = 1, .reload = Reload::kLive,
       .description = "The capture is bad when the solve uses fewer than this fraction of the face markers."},
      {FACECAP_KEY(quality.head_held_degraded), .default_value = 0.05, .min = 0, .max = 1, .reload = Reload::kLive,
       .description = "The capture is degraded when more than this fraction of a window's frames held the head pose "
                      "(too few head markers to fit it)."},
      {FACECAP_KEY(quality.head_held_bad), .default_value = 0.5, .min = 0, .max = 1, .reload = Reload::kLive,
       .description = "The capture is bad when more than this fraction of the frames held the head pose."},
      {FACECAP_KEY(quality.residual_p95_degraded_mm), .default_value = 1.5, .unit = "mm", .min = 0, .max = 1000,
       .reload = Reload::kLive,
       .description = "The capture is degraded when the 95th percentile of the markers' fit residuals (solved surface "
                      "point vs marker target) over a window is above this."},
      {FACECAP_KEY(quality.residual_p95_bad_mm), .default_value = 4.0, .unit = "mm", .min = 0, .max = 1000,
       .reload = Reload::kLive,
       .description = "The capture is bad when the residuals' 95th percentile is above this."},
      {FACECAP_KEY(quality.noise_degraded_mm), .default_value = 0.5, .unit = "mm", .min = 0, .max = 1000,
       .reload = Reload::kLive,
       .description = "The capture is degraded when the median marker's noise over a window is above this, or names "
                      "each marker noisier than this. A marker's noise is measured from the data: the second "
                      "difference of its position over three consecutive frames, as a standard deviation per "
                      "coordinate (the face's own motion adds a few hundredths of a millimetre at capture rates)."},
      {FACECAP_KEY(quality.noise_bad_mm), .default_value = 2.0, .unit = "mm", .min = 0, .max = 1000,
       .reload = Reload::kLive, .description = "The capture is bad when the median marker's noise is above this."},
      {FACECAP_KEY(quality.hold_s), .default_value = 3.0, .unit = "s", .min = 0, .max = 600, .reload = Reload::kLive,
       .description = "The quality shown changes only once every status window for this long agrees on the new "
                      "state (hysteresis: a capture at the edge of a threshold does not flap); 0 follows every "
                      "window."},

      {FACECAP_CHOICE_KEY(logging.level, kLogLevels), .default_value = std::string("info"),
       .reload = Reload::kLive, .description = "Least severe log level written."},
      {FACECAP_KEY(logging.stats_interval_s), .default_value = 10.0, .unit = "s", .min = 0, .max = 86400,
       .reload = Reload::kLive, .description = "How often the loop's figures are logged; 0 never."},
      {FACECAP_KEY(logging.stats_file), .default_value = std::string(),
       .description = "When facecapd stops, write its final figures as JSON to this file (benchmarks)."},
  };
  return rows;
}

#undef FACECAP_MARKER_DEVICE_KEYS
#undef FACECAP_KEY

const SectionSpec kSections[] = {
    {"", ""},
    {"source", "Where marker frames come from."},
    {"source.sim", "The simulated capture system (source.driver = \"sim\")."},
    {"source.replay", "Playing a recorded take (source.driver = \"replay\")."},
    {"source.usb", "A marker device on USB bulk transfers (source.driver = \"usb\", docs/usb-hid-protocol.md)."},
    {"source.hid", "A marker device sending HID reports (source.driver = \"hid\", docs/usb-hid-protocol.md)."},
    {"source.v4l2", "Calibrated IR cameras over V4L2 (source.driver = \"v4l2\", docs/cameras.md)."},
    {"source.natnet", "OptiTrack NatNet over UDP (source.driver = \"natnet\"; docs/natnet.md)."},
    {"rig", "The blendshape rig the markers are solved onto."},
    {"calibration", "How markers relate to the rig."},
    {"solver", "The per-frame face solve (the paper's Eq. 2-5)."},
    {"filter", "Temporal filtering of the marker targets (and optionally the weights) before the solve "
               "(docs/solver.md, \"Temporal filter\")."},
    {"loop", "The real-time solve loop."},
    {"outputs.shm", "The shared-memory output renderers read (docs/shm-format.md)."},
    {"outputs.recording", "Recording what the daemon receives and solves (.fcrec, docs/recording-format.md). "
                          "Formerly [recording], which is still read, with a warning."},
    {"outputs.udp", "facecap's own UDP stream: weights, head pose and optionally vertices, unicast or multicast "
                    "(docs/udp-stream.md)."},
    {"outputs.vmc", "OSC with the VMC protocol, for VTuber software and VMC receivers (docs/outputs.md)."},
    {"outputs.livelink", "Unreal Live Link Face packets (docs/outputs.md)."},
    {"control", "Supervision by systemd and run control."},
    {"control.http", "The control API over HTTP/JSON and WebSocket (docs/control-api.md)."},
    {"quality", "The capture-quality state (good / degraded / bad) that STATUS, the log, the stats file and the "
                "control API show for each status window; the worst criterion decides."},
    {"logging", "Logs and figures."},
};

}  // namespace

std::string_view value_type_name(ValueType type) noexcept {
  switch (type) {
    case ValueType::kBool: return "boolean";
    case ValueType::kInt: return "integer";
    case ValueType::kFloat: return "number";
    case ValueType::kString: return "string";
    case ValueType::kIntList: return "array of integers";
    case ValueType::kChoice: return "string";
  }
  return "?";
}

std::string_view KeySpec::section() const noexcept {
  const auto dot = path.rfind('.');
  return dot == std::string_view::npos ? std::string_view() : path.substr(0, dot);
}

std::string_view KeySpec::name() const noexcept {
  const auto dot = path.rfind('.');
  return dot == std::string_view::npos ? path : path.substr(dot + 1);
}

std::span<const KeySpec> config_schema() { return schema_rows(); }
std::span<const SectionSpec> config_sections() { return kSections; }

const KeySpec* find_key(std::string_view path) noexcept {
  for (const KeySpec& key : schema_rows())
    if (key.path == path) return &key;
  return nullptr;
}

ValueType KeySpec::type() const noexcept {
  // The variant's alternatives in ValueType order, then int members as integers.
  return field.index() == std::variant_size_v<Field> - 1 ? ValueType::kInt : ValueType(field.index());
}

std::vector<Choice> KeySpec::choices() const {
  const auto* choice = std::get_if<ChoiceField>(&field);
  return choice ? choice->choices() : std::vector<Choice>{};
}

Value get_value(const KeySpec& key, const DaemonConfig& config) {
  auto& mutable_config = const_cast<DaemonConfig&>(config);  // the accessors only read here
  return std::visit(
      [&](const auto& field) -> Value {
        using F = std::decay_t<decltype(field)>;
        if constexpr (std::is_same_v<F, ChoiceField>) return std::string(field.get(config));
        else if constexpr (std::is_same_v<F, int& (*)(DaemonConfig&)>) return int64_t{field(mutable_config)};
        else return field(mutable_config);
      },
      key.field);
}

void set_value(const KeySpec& key, DaemonConfig& config, const Value& value) {
  std::visit(
      [&](const auto& field) {
        using F = std::decay_t<decltype(field)>;
        if constexpr (std::is_same_v<F, ChoiceField>) {
          if (!field.set(config, std::get<std::string>(value)))
            throw Error(fmt::format("\"{}\" is not one of {}'s choices", std::get<std::string>(value), key.path));
        } else if constexpr (std::is_same_v<F, int& (*)(DaemonConfig&)>) {
          field(config) = int(std::get<int64_t>(value));  // the key's range keeps it within int
        } else {
          using T = std::remove_reference_t<decltype(field(config))>;
          field(config) = std::get<T>(value);
        }
      },
      key.field);
}

DaemonConfig default_config() {
  DaemonConfig config;
  for (const KeySpec& key : schema_rows()) set_value(key, config, key.default_value);
  return config;
}

namespace {

std::string quote(std::string_view text) {
  std::string out = "\"";
  for (const char c : text) {
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\t': out += "\\t"; break;
      default:
        if ((unsigned char)c < 0x20) out += fmt::format("\\u{:04x}", unsigned(c));
        else out += c;
    }
  }
  return out + "\"";
}

std::string format_number(double v) {
  std::string text = fmt::format("{}", v);
  if (text.find_first_of(".eEin") == std::string::npos) text += ".0";  // stays a TOML float
  return text;
}

}  // namespace

std::string format_value(const Value& value) {
  struct Formatter {
    std::string operator()(bool v) const { return v ? "true" : "false"; }
    std::string operator()(int64_t v) const { return fmt::format("{}", v); }
    std::string operator()(double v) const { return format_number(v); }
    std::string operator()(const std::string& v) const { return quote(v); }
    std::string operator()(const std::vector<int64_t>& v) const { return fmt::format("[{}]", fmt::join(v, ", ")); }
  };
  return std::visit(Formatter{}, value);
}

std::string allowed_range(const KeySpec& key) {
  if (key.type() == ValueType::kChoice) {
    std::vector<std::string_view> names;
    for (const Choice& c : key.choices()) names.push_back(c.name);
    return fmt::format("one of: {}", fmt::join(names, ", "));
  }
  const bool numeric = key.type() == ValueType::kInt || key.type() == ValueType::kFloat || key.type() == ValueType::kIntList;
  if (!numeric || (std::isinf(key.min) && std::isinf(key.max))) return {};
  const std::string unit = key.unit.empty() ? "" : fmt::format(" {}", key.unit);
  const std::string prefix = key.type() == ValueType::kIntList ? "each " : "";
  if (key.min == key.max) return fmt::format("{}exactly {}", prefix, key.min);
  return fmt::format("{}{} to {}{}", prefix, key.min, key.max, unit);
}

}  // namespace facecap::config
