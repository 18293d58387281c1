// nlosplan: the sum over samples of the convolutions of a Lambertian object's two legs, as an XLA FFI handler (CPU).
//
// out[z, t] = sum_m sum_u b[m, z, u] a[m, t - u]: a (m, n1) is each sample's light from the lit wall (leg 1) and
// b (m, z, n2) its return to each zone through the detection cells (leg 2), both on the node grid; out (z, n1 +
// n2 - 1). The XLA path (nlosplan.sensor_models.transient.sum_convolve) does this with FFTs of every (sample,
// zone) row and a product of the spectra summed over samples. Both legs are sparse in time: a sample's leg 1
// covers the nodes between its nearest and farthest lit cell, and a zone's few detection cells put leg 2 on a
// handful of nodes. So this adds a[m]'s non-zero span, scaled, at each non-zero node of b[m, z] (exact sums, no
// FFT round-off): contiguous vector loops, 0.47 ms a DENALI scene against ~1.8 ms for the FFTs and the product
// (issue 20's profile, docs/fast-simulator.md).
//
// Shapes: a (B, m, n1), b (B, m, z, n2) with B >= 1 leading batch entries (vmap); out (B, z, n1 + n2 - 1).
// Built on first use by nlosplan/sensor_models/compiled.py with the C++ compiler and the headers in jaxlib.
#include <cstdint>
#include <cstring>

#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

// The inner loop is a contiguous multiply-add; AVX2 doubles its width where the CPU has it (chosen at load
// time, so the library still runs on any x86-64; other architectures build the default only).
#if defined(__x86_64__) && defined(__GNUC__)
#define NLOSPLAN_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define NLOSPLAN_CLONES
#endif

template <typename T>
NLOSPLAN_CLONES void SumConvolve(const T* a, const T* b, T* out, int64_t batch, int64_t m, int64_t n1, int64_t z,
                                 int64_t n2) {
  const int64_t len = n1 + n2 - 1;
  std::memset(out, 0, sizeof(T) * static_cast<size_t>(batch * z * len));
  for (int64_t e = 0; e < batch; ++e) {
    const T* ae = a + e * m * n1;
    const T* be = b + e * m * z * n2;
    T* oe = out + e * z * len;
    for (int64_t i = 0; i < m; ++i) {
      const T* ai = ae + i * n1;
      int64_t lo = 0, hi = n1;  // the non-zero span of this sample's leg 1
      while (lo < hi && ai[lo] == T(0)) ++lo;
      while (hi > lo && ai[hi - 1] == T(0)) --hi;
      if (lo == hi) continue;
      const T* span = ai + lo;
      const int64_t width = hi - lo;
      for (int64_t k = 0; k < z; ++k) {
        const T* bk = be + (i * z + k) * n2;
        T* ok = oe + k * len + lo;
        for (int64_t u = 0; u < n2; ++u) {
          const T v = bk[u];
          if (v == T(0)) continue;
          T* o = ok + u;
          for (int64_t t = 0; t < width; ++t) o[t] += v * span[t];
        }
      }
    }
  }
}

ffi::Error SumConvolveImpl(ffi::AnyBuffer a, ffi::AnyBuffer b, ffi::Result<ffi::AnyBuffer> out, int64_t m, int64_t n1,
                           int64_t z, int64_t n2) {
  const auto type = a.element_type();
  if (b.element_type() != type || out->element_type() != type) {
    return ffi::Error::InvalidArgument("nlosplan sum_convolve: both legs and the output must share one float type");
  }
  if (m < 1 || n1 < 1 || z < 1 || n2 < 1) return ffi::Error::InvalidArgument("nlosplan sum_convolve: empty legs");
  const int64_t count = static_cast<int64_t>(a.element_count());
  if (count % (m * n1) != 0) return ffi::Error::InvalidArgument("nlosplan sum_convolve: leg 1 is not (B, m, n1)");
  const int64_t batch = count / (m * n1);
  if (static_cast<int64_t>(b.element_count()) != batch * m * z * n2 ||
      static_cast<int64_t>(out->element_count()) != batch * z * (n1 + n2 - 1)) {
    return ffi::Error::InvalidArgument("nlosplan sum_convolve: leg 2 or the output does not match leg 1");
  }
  if (type == ffi::F32) {
    SumConvolve(a.typed_data<float>(), b.typed_data<float>(), out->typed_data<float>(), batch, m, n1, z, n2);
  } else if (type == ffi::F64) {
    SumConvolve(a.typed_data<double>(), b.typed_data<double>(), out->typed_data<double>(), batch, m, n1, z, n2);
  } else {
    return ffi::Error::InvalidArgument("nlosplan sum_convolve: float32 or float64 only");
  }
  return ffi::Error::Success();
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(NlosplanSumConvolve, SumConvolveImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Ret<ffi::AnyBuffer>()
                                  .Attr<int64_t>("m")
                                  .Attr<int64_t>("n1")
                                  .Attr<int64_t>("z")
                                  .Attr<int64_t>("n2"));
