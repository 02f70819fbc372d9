/* facecap client: read solved faces that facecapd publishes in shared memory.
 *
 * Plain C so that renderers in any language can bind it; no allocation after open, no
 * locks, and the writer is never slowed down by readers (they map the segment read-only).
 * Layout and protocol: docs/shm-format.md.
 *
 *   facecap_client* c = NULL;
 *   if (facecap_client_open("facecap", &c) != FACECAP_OK) ...;
 *   facecap_frame f;
 *   while (facecap_client_wait_next(c, &f, 100000000) >= 0) { use f.weights[0 .. f.shape_count) }
 *   facecap_client_close(c);
 *
 * A facecap_client is not thread-safe: use one per reading thread.
 */
#ifndef FACECAP_CLIENT_H
#define FACECAP_CLIENT_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum facecap_status {
  FACECAP_OK = 0,
  FACECAP_NO_FRAME = 1,         /* nothing new yet (or the wait timed out) */
  FACECAP_RESTARTED = 2,        /* a new writer replaced the old one: shapes may differ, re-query them */
  FACECAP_WRITER_STALLED = 3,   /* the writer's process lives and holds the segment but stopped beating
                                   (stopped, hung); frames may resume */
  FACECAP_ERR_ARGUMENT = -1,    /* NULL pointer or bad name */
  FACECAP_ERR_NOT_FOUND = -2,   /* no segment of that name (is facecapd running?) */
  FACECAP_ERR_ACCESS = -3,      /* permission denied (join the facecap group) */
  FACECAP_ERR_LAYOUT = -4,      /* not a facecap segment, or a layout version this library does not read */
  FACECAP_ERR_WRITER_GONE = -5, /* the writer stopped or stopped beating, and no new one appeared */
  FACECAP_ERR_CONTENDED = -6,   /* the slot kept changing while being read (reader far too slow) */
  FACECAP_ERR_SYSTEM = -7       /* another system error; see errno */
} facecap_status;

/* One solved frame. Pointers refer to storage inside the facecap_client and stay valid
 * until the next read on the same client. Times are CLOCK_MONOTONIC nanoseconds. */
typedef struct facecap_frame {
  uint64_t sequence;            /* publish counter: consecutive frames differ by 1 */
  uint64_t dropped;             /* frames published since the previous read and never returned */
  int64_t frame_no;             /* the source's frame number */
  int64_t source_time_ns;       /* the source's own clock */
  int64_t receive_time_ns;      /* the frame reached facecapd */
  int64_t solve_start_ns;
  int64_t solve_end_ns;
  int64_t publish_time_ns;      /* the slot was released to readers */
  float head_rotation_wxyz[4];
  float head_translation[3];
  uint32_t flags;
  uint32_t markers_used;
  uint32_t shape_count;
  uint32_t vertex_count;        /* 0 when the writer does not publish vertices */
  const float* weights;         /* shape_count values */
  const float* vertices;        /* vertex_count * 3 values (x, y, z per vertex), or NULL */
} facecap_frame;

typedef struct facecap_client facecap_client;

/* Maps the segment `name` ("facecap" or "/facecap") read-only and checks its layout. */
int facecap_client_open(const char* name, facecap_client** out_client);
void facecap_client_close(facecap_client* client);

uint32_t facecap_client_shape_count(const facecap_client* client);
/* NUL-terminated name of shape i, or NULL when out of range. */
const char* facecap_client_shape_name(const facecap_client* client, uint32_t index);
uint32_t facecap_client_vertex_count(const facecap_client* client);
double facecap_client_nominal_rate_hz(const facecap_client* client);
const char* facecap_client_rig_name(const facecap_client* client);
int32_t facecap_client_writer_pid(const facecap_client* client);

/* The newest published frame (FACECAP_NO_FRAME when nothing was published yet). */
int facecap_client_read_latest(facecap_client* client, facecap_frame* out_frame);
/* The frame after the one last read; when the writer has lapped the reader, the oldest
 * frame still in the ring, with out_frame->dropped saying how many were lost. */
int facecap_client_read_next(facecap_client* client, facecap_frame* out_frame);
/* read_next, waiting up to timeout_ns (polling, no locks). While nothing arrives it checks
 * whether the writer is gone, was replaced or is stalled (FACECAP_ERR_WRITER_GONE,
 * FACECAP_RESTARTED, FACECAP_WRITER_STALLED: each returned at once). */
int facecap_client_wait_next(facecap_client* client, facecap_frame* out_frame, int64_t timeout_ns);

/* FACECAP_OK while the writer runs and beats; FACECAP_RESTARTED after remapping a new
 * writer's segment; when it has not beaten for stale_after_ns, FACECAP_WRITER_STALLED if
 * its process still holds the segment's writer lock, else FACECAP_ERR_WRITER_GONE (also
 * after a clean stop). */
int facecap_client_check_writer(facecap_client* client, int64_t stale_after_ns);

const char* facecap_status_string(int status);

#ifdef __cplusplus
}
#endif

#endif /* FACECAP_CLIENT_H */
