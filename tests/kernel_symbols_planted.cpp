// A kernel object gone wrong, for kernels:a_planted_shared_symbol_is_reported: besides its
// own namespace it defines an inline function that every object using it would share.
namespace facecap::kernels::avx2 {
float kernel_table_stand_in(float x);
}

inline float planted_widest_lane(float a, float b) { return a > b ? a : b; }

float facecap::kernels::avx2::kernel_table_stand_in(float x) {
  float (*volatile keep)(float, float) = planted_widest_lane;  // taken by address: emitted out of line
  return keep(x, 1.0f);
}
