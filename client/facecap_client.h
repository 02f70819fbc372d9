/* facecap client: read the solved faces facecapd publishes, from shared memory on the
 * same machine or from its UDP stream over the network.
 *
 * Plain C so that renderers in any language can bind it. Shared memory: no allocation after
 * open, no locks, and the writer is never slowed down by readers (they map the segment
 * read-only). UDP: datagrams are reassembled into the same frames. Layouts and protocols:
 * docs/shm-format.md, docs/udp-stream.md; a guide with whole examples: docs/subscribers.md.
 *
 *   facecap_client* c = NULL;
 *   if (facecap_client_open("facecap", &c) != FACECAP_OK) ...;   // or facecap_client_open_udp
 *   facecap_frame f;
 *   while (facecap_client_wait_next(c, &f, 100000000) >= 0) { use f.weights[0 .. f.shape_count) }
 *   facecap_client_close(c);
 *
 * A facecap_client is not thread-safe: use one per reading thread.
 */
#ifndef FACECAP_CLIENT_H
#define FACECAP_CLIENT_H

#include <stdint.h>

#if defined(__GNUC__)
#define FACECAP_CLIENT_API __attribute__((visibility("default")))
#else
#define FACECAP_CLIENT_API
#endif

#ifdef __cplusplus
extern "C" {
#endif

typedef enum facecap_status {
  FACECAP_OK = 0,
  FACECAP_NO_FRAME = 1,         /* nothing new yet (or the wait timed out) */
  FACECAP_RESTARTED = 2,        /* a new writer (or, over UDP, a first or changed schema): re-query the shapes */
  FACECAP_ERR_ARGUMENT = -1,    /* NULL pointer, bad name or bad address */
  FACECAP_ERR_NOT_FOUND = -2,   /* no segment of that name (is facecapd running?) */
  FACECAP_ERR_ACCESS = -3,      /* permission denied (join the facecap group) */
  FACECAP_ERR_LAYOUT = -4,      /* not a facecap segment, or a layout version this library does not read */
  FACECAP_ERR_WRITER_GONE = -5, /* the writer stopped or went silent, and no new one appeared (yet) */
  FACECAP_ERR_CONTENDED = -6,   /* the slot kept changing while being read (reader far too slow) */
  FACECAP_ERR_SYSTEM = -7,      /* another system error; see errno */
  FACECAP_ERR_ADDRESS = -8      /* UDP: cannot receive on that address (in use, not of this host, no such interface) */
} facecap_status;

/* One solved frame. Pointers refer to storage inside the facecap_client and stay valid
 * until the next read on the same client. Times are CLOCK_MONOTONIC nanoseconds of the
 * machine facecapd runs on. */
typedef struct facecap_frame {
  uint64_t sequence;            /* publish counter: consecutive frames differ by 1 */
  uint64_t dropped;             /* frames published since the previous read and never returned */
  int64_t frame_no;             /* the source's frame number */
  int64_t source_time_ns;       /* the source's own clock */
  int64_t receive_time_ns;      /* the frame reached facecapd */
  int64_t solve_start_ns;
  int64_t solve_end_ns;
  int64_t publish_time_ns;      /* shm: the slot was released to readers; UDP: the frame was sent */
  float head_rotation_wxyz[4];
  float head_translation[3];
  uint32_t flags;               /* why a frame may be less than it should be (docs/shm-format.md, "Frame flags") */
  uint32_t markers_used;
  uint32_t shape_count;
  uint32_t vertex_count;        /* 0 when the writer does not publish vertices */
  uint8_t timecode_hours, timecode_minutes, timecode_seconds, timecode_frames;
  uint32_t timecode_rate_hz;    /* 0: the source gave no timecode */
  float timecode_subframe;
  uint64_t rig_hash;            /* identity of the solved rig */
  const float* weights;         /* shape_count values */
  const float* vertices;        /* vertex_count * 3 values (x, y, z per vertex), or NULL */
} facecap_frame;                /* no padding on LP64: bindings (ctypes, ...) can mirror it field by field */

typedef struct facecap_client facecap_client;

/* Maps the shared-memory segment `name` ("facecap" or "/facecap") read-only and checks its layout. */
FACECAP_CLIENT_API int facecap_client_open(const char* name, facecap_client** out_client);
/* Receives facecapd's UDP stream on "ADDRESS:PORT" ("[ADDRESS]:PORT" for IPv6): an address of
 * this machine ("127.0.0.1", "0.0.0.0" for all) or a multicast group to join
 * ("239.255.70.67:39540"), on the interface named `interface_name` ("eth0"; NULL for the
 * system's choice). Frames come once the first schema has arrived (facecapd repeats it every
 * second); that read returns FACECAP_RESTARTED. */
FACECAP_CLIENT_API int facecap_client_open_udp(const char* address, const char* interface_name,
                                               facecap_client** out_client);
FACECAP_CLIENT_API void facecap_client_close(facecap_client* client);

FACECAP_CLIENT_API uint32_t facecap_client_shape_count(const facecap_client* client);
/* NUL-terminated name of shape i, or NULL when out of range. */
FACECAP_CLIENT_API const char* facecap_client_shape_name(const facecap_client* client, uint32_t index);
/* ARKit name of shape i ("JawOpen" for jawOpen), "" when the shape has none, NULL when out of range. */
FACECAP_CLIENT_API const char* facecap_client_arkit_name(const facecap_client* client, uint32_t index);
FACECAP_CLIENT_API uint32_t facecap_client_vertex_count(const facecap_client* client);
/* Frames per second the writer publishes (shm: the loop's rate; UDP: the rate it sends at). */
FACECAP_CLIENT_API double facecap_client_nominal_rate_hz(const facecap_client* client);
FACECAP_CLIENT_API const char* facecap_client_rig_name(const facecap_client* client);
FACECAP_CLIENT_API uint64_t facecap_client_rig_hash(const facecap_client* client);
/* shm: the writer's process id; UDP: 0 (the writer may be on another machine). */
FACECAP_CLIENT_API int32_t facecap_client_writer_pid(const facecap_client* client);
/* UDP: frames given up because some of their datagrams never arrived; shm: 0. */
FACECAP_CLIENT_API uint64_t facecap_client_incomplete_frames(const facecap_client* client);

/* The newest frame (FACECAP_NO_FRAME when nothing new was published; over UDP, when nothing
 * arrived since the last read). */
FACECAP_CLIENT_API int facecap_client_read_latest(facecap_client* client, facecap_frame* out_frame);
/* The frame after the one last read; when the writer has lapped the reader, the oldest
 * frame still in the ring, with out_frame->dropped saying how many were lost. */
FACECAP_CLIENT_API int facecap_client_read_next(facecap_client* client, facecap_frame* out_frame);
/* read_next, waiting up to timeout_ns. While nothing arrives it checks whether the writer
 * is gone or was replaced (FACECAP_ERR_WRITER_GONE, FACECAP_RESTARTED). */
FACECAP_CLIENT_API int facecap_client_wait_next(facecap_client* client, facecap_frame* out_frame, int64_t timeout_ns);

/* FACECAP_OK while the writer runs and beats; FACECAP_RESTARTED after following a new
 * writer; FACECAP_ERR_WRITER_GONE when it stopped or has been silent for stale_after_ns
 * (UDP: three schema intervals, whatever stale_after_ns says). */
FACECAP_CLIENT_API int facecap_client_check_writer(facecap_client* client, int64_t stale_after_ns);

FACECAP_CLIENT_API const char* facecap_status_string(int status);

#ifdef __cplusplus
}
#endif

#endif /* FACECAP_CLIENT_H */
