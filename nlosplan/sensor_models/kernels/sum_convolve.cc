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
//
// Also here (one translation unit: each source compiles on its own core, and parsing the FFI header is most of
// a compile, so a third source cost a cold start ~4 s on 2 cores): DepositConvolve, a Lambertian object's
// detection leg deposited and convolved with its illumination leg in one pass. The same sums as the deposit
// (deposit.cc) of the detection leg's arrivals into b (m, z, n2) followed by SumConvolve, in the same order, so
// the result is the same to the bit. What it saves is b itself: for DENALI's mount, 144 samples x 9 zones x 192 nodes (1 MB a scene) were
// zeroed, written on a handful of nodes per row and scanned again for those nodes. Here one sample's rows live in a
// small buffer (z x n2, a few KB, in L1), each zone's touched nodes are known as they are written, and only they
// are convolved and cleared (issue 38's profile: the deposit and the scan were most of a mount scene's time).
//
// Shapes: a (B, m, n1); p, w (B, m, L) the detection leg's fractional node positions and weights (L cells per
// sample); r (B, L) or (L,) per batch entry, each cell's zone (its row within the sample's z rows; rows out of
// range are dropped, as the deposit drops them); out (B, z, n1 + n2 - 1). B >= 1 leading batch entries (vmap).
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <vector>

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

// Touched detection nodes convolved together (DepositConvolve): the unrolled sum below is written for 4.
constexpr int64_t kBlock = 4;

// The non-zero span [lo, hi) of a sample's leg 1 (row of n nodes); false when the row is all zeros.
template <typename T>
inline bool NonZeroSpan(const T* row, int64_t n, int64_t* lo, int64_t* hi) {
  int64_t a = 0, b = n;
  while (a < b && row[a] == T(0)) ++a;
  while (b > a && row[b - 1] == T(0)) --b;
  *lo = a;
  *hi = b;
  return a < b;
}

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
      int64_t lo, hi;
      if (!NonZeroSpan(ai, n1, &lo, &hi)) continue;
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

template <typename T>
NLOSPLAN_CLONES void DepositConvolve(const T* a, const T* p, const T* w, const int32_t* r, T* out, int64_t batch,
                                     int64_t m, int64_t n1, int64_t cells, int64_t r_stride, int64_t z,
                                     int64_t n2) {
  const int64_t len = n1 + n2 - 1;
  std::memset(out, 0, sizeof(T) * static_cast<size_t>(batch * z * len));
  std::vector<T> buf(static_cast<size_t>(z * n2), T(0));  // one sample's detection rows
  std::vector<int64_t> lo_z(static_cast<size_t>(z)), hi_z(static_cast<size_t>(z));  // touched nodes [lo, hi)
  std::vector<T> padded(static_cast<size_t>(n1 + 2 * (kBlock - 1)), T(0));  // leg 1's span between zeros
  const T inner = static_cast<T>(n2 - 1);
  const T last = static_cast<T>(n2);
  for (int64_t e = 0; e < batch; ++e) {
    const T* ae = a + e * m * n1;
    const T* pe = p + e * m * cells;
    const T* we = w + e * m * cells;
    const int32_t* re = r + e * r_stride;
    T* oe = out + e * z * len;
    for (int64_t i = 0; i < m; ++i) {
      const T* ai = ae + i * n1;
      int64_t lo, hi;
      if (!NonZeroSpan(ai, n1, &lo, &hi)) continue;  // no light reaches the sample: its detection leg adds nothing
      for (int64_t k = 0; k < z; ++k) {
        lo_z[k] = n2;
        hi_z[k] = 0;
      }
      // the deposit of deposit.cc, onto this sample's rows
      const T* pi = pe + i * cells;
      const T* wi = we + i * cells;
      for (int64_t j = 0; j < cells; ++j) {
        const T wk = wi[j];
        const T pk = pi[j];
        const int64_t row = re[j];
        const bool row_ok = static_cast<uint64_t>(row) < static_cast<uint64_t>(z);
        if (__builtin_expect((pk >= T(0)) & (pk < inner) & row_ok, 1)) {  // both nodes on the grid
          const int64_t i0 = static_cast<int64_t>(pk);
          const T f = pk - static_cast<T>(i0);
          T* o = buf.data() + row * n2 + i0;
          o[0] += wk * (T(1) - f);
          o[1] += wk * f;
          if (i0 < lo_z[row]) lo_z[row] = i0;
          if (i0 + 2 > hi_z[row]) hi_z[row] = i0 + 2;
        } else if ((pk > T(-1)) & (pk < last) & row_ok) {  // one node on the grid (NaN fails both tests)
          const int64_t i0 = pk < T(0) ? -1 : n2 - 1;
          const T f = pk - static_cast<T>(i0);
          T* o = buf.data() + row * n2;
          if (i0 >= 0) o[i0] += wk * (T(1) - f);
          if (i0 + 1 < n2) o[i0 + 1] += wk * f;
          const int64_t first = i0 >= 0 ? i0 : 0, end = i0 + 2 < n2 ? i0 + 2 : n2;
          if (first < lo_z[row]) lo_z[row] = first;
          if (end > hi_z[row]) hi_z[row] = end;
        }
      }
      // sum_convolve.cc's loop over the touched nodes only, clearing them for the next sample
      const T* __restrict__ span = ai + lo;  // leg 1 and the output never overlap
      const int64_t width = hi - lo;
      // leg 1's span with kBlock - 1 zeros on each side, for the blocks of touched nodes below
      std::memcpy(padded.data() + (kBlock - 1), span, sizeof(T) * static_cast<size_t>(width));
      std::fill(padded.begin() + (kBlock - 1) + width, padded.begin() + 2 * (kBlock - 1) + width, T(0));
      const T* __restrict__ sp = padded.data();
      for (int64_t k = 0; k < z; ++k) {
        T* bk = buf.data() + k * n2;
        T* ok = oe + k * len + lo;
        int64_t u = lo_z[k];
        // kBlock touched nodes at once: each output node takes their terms in the order of the loop below (node u
        // first), so the sums are the same to the bit, with one load and store of the output per kBlock terms. A zero
        // node adds 0 * leg 1 = 0 (leg 1 is finite), which leaves every sum as it is.
        for (; u + kBlock <= hi_z[k]; u += kBlock) {
          const T v0 = bk[u], v1 = bk[u + 1], v2 = bk[u + 2], v3 = bk[u + 3];
          bk[u] = bk[u + 1] = bk[u + 2] = bk[u + 3] = T(0);
          if ((v0 == T(0)) & (v1 == T(0)) & (v2 == T(0)) & (v3 == T(0))) continue;
          T* __restrict__ o = ok + u;
          for (int64_t t = 0; t < width + kBlock - 1; ++t) {
            o[t] = (((o[t] + v0 * sp[t + 3]) + v1 * sp[t + 2]) + v2 * sp[t + 1]) + v3 * sp[t];
          }
        }
        for (; u < hi_z[k]; ++u) {
          const T v = bk[u];
          bk[u] = T(0);
          if (v == T(0)) continue;
          T* __restrict__ o = ok + u;
          for (int64_t t = 0; t < width; ++t) o[t] += v * span[t];
        }
      }
    }
  }
}

ffi::Error DepositConvolveImpl(ffi::AnyBuffer a, ffi::AnyBuffer p, ffi::AnyBuffer w, ffi::Buffer<ffi::S32> r,
                               ffi::Result<ffi::AnyBuffer> out, int64_t m, int64_t n1, int64_t cells, int64_t z,
                               int64_t n2) {
  const auto type = a.element_type();
  if (p.element_type() != type || w.element_type() != type || out->element_type() != type) {
    return ffi::Error::InvalidArgument(
        "nlosplan deposit_convolve: leg 1, positions, weights and output must share one float type");
  }
  if (m < 1 || n1 < 1 || cells < 1 || z < 1 || n2 < 1) {
    return ffi::Error::InvalidArgument("nlosplan deposit_convolve: empty legs");
  }
  const int64_t count = static_cast<int64_t>(a.element_count());
  if (count % (m * n1) != 0) return ffi::Error::InvalidArgument("nlosplan deposit_convolve: leg 1 is not (B, m, n1)");
  const int64_t batch = count / (m * n1);
  const int64_t r_count = static_cast<int64_t>(r.element_count());
  if (static_cast<int64_t>(p.element_count()) != batch * m * cells ||
      static_cast<int64_t>(w.element_count()) != batch * m * cells ||
      (r_count != cells && r_count != batch * cells) ||
      static_cast<int64_t>(out->element_count()) != batch * z * (n1 + n2 - 1)) {
    return ffi::Error::InvalidArgument("nlosplan deposit_convolve: positions, weights, zones or output do not match");
  }
  const int64_t r_stride = r_count == cells ? 0 : cells;
  if (type == ffi::F32) {
    DepositConvolve(a.typed_data<float>(), p.typed_data<float>(), w.typed_data<float>(), r.typed_data(),
                    out->typed_data<float>(), batch, m, n1, cells, r_stride, z, n2);
  } else if (type == ffi::F64) {
    DepositConvolve(a.typed_data<double>(), p.typed_data<double>(), w.typed_data<double>(), r.typed_data(),
                    out->typed_data<double>(), batch, m, n1, cells, r_stride, z, n2);
  } else {
    return ffi::Error::InvalidArgument("nlosplan deposit_convolve: float32 or float64 only");
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

XLA_FFI_DEFINE_HANDLER_SYMBOL(NlosplanDepositConvolve, DepositConvolveImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::Buffer<ffi::S32>>()
                                  .Ret<ffi::AnyBuffer>()
                                  .Attr<int64_t>("m")
                                  .Attr<int64_t>("n1")
                                  .Attr<int64_t>("cells")
                                  .Attr<int64_t>("z")
                                  .Attr<int64_t>("n2"));
