/* The client API compiled as C (renderers in C or through C FFI use it this way). */
#include <stdio.h>
#include <string.h>

#include "client/facecap_client.h"

int main(void) {
  facecap_client* client = NULL;
  const int status = facecap_client_open("facecap-test-c-api-no-such-segment", &client);
  if (status != FACECAP_ERR_NOT_FOUND || client != NULL) {
    fprintf(stderr, "open of a missing segment: %d (%s)\n", status, facecap_status_string(status));
    return 1;
  }
  facecap_frame frame;
  memset(&frame, 0, sizeof frame);
  if (facecap_client_read_next(NULL, &frame) != FACECAP_ERR_ARGUMENT) return 1;
  if (facecap_client_shape_count(NULL) != 0 || facecap_client_shape_name(NULL, 0) != NULL) return 1;
  printf("C API: %s\n", facecap_status_string(status));
  return 0;
}
