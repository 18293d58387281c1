// nlosplan: the arrival-time deposit of nlosplan.sensor_models.transient.deposit_at as an XLA FFI handler (CPU).
//
// Each arrival k (fractional node position p[k], weight w[k], row r[k]) puts (1 - f) w[k] on node floor(p[k]) and
// f w[k] on the next node of its row (f = p[k] - floor(p[k])); nodes off the grid and rows out of range are dropped.
// One pass over the arrivals, each row taking its arrivals in their order (a row per sample: four samples at once,
// see kInterleave): the same sums as XLA's scatter-add, without its per-update index checks, update windows and
// materialized update arrays.
//
// Shapes: p, w (B, N) with B >= 1 leading batch entries (vmap); r (B, N), or (B, L) with N a multiple of L for
// rows that follow the blocks of L arrivals (the last axis of a samples x cells array: arrival k is in row
// (k div L) * step + r[k mod L]; step = 0 repeats the same rows, step = 1 with r = 0 is a row per sample); out
// (B, n_rows, n_nodes). Built on first use by
// nlosplan/sensor_models/compiled.py with the C++ compiler and the headers shipped in jaxlib.
#include <cstdint>
#include <cstring>

#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

// One arrival (position pk, weight wk) onto its row of n_nodes nodes (see the file's comment).
template <typename T>
inline void Add(T pk, T wk, int64_t row, T* ob, int64_t n_rows, int64_t n_nodes, T inner, T last) {
  const bool row_ok = static_cast<uint64_t>(row) < static_cast<uint64_t>(n_rows);
  // No test of the weight: zero weights (samples facing away) are common and unpredictable, and a
  // mispredicted branch costs more than adding zeros (2-3x on DENALI scenes).
  if (__builtin_expect((pk >= T(0)) & (pk < inner) & row_ok, 1)) {  // both nodes on the grid
    const int64_t i0 = static_cast<int64_t>(pk);  // truncation is the floor here
    const T f = pk - static_cast<T>(i0);
    T* o = ob + row * n_nodes + i0;
    o[0] += wk * (T(1) - f);
    o[1] += wk * f;
  } else if ((pk > T(-1)) & (pk < last) & row_ok) {  // one node on the grid (NaN fails both tests)
    const int64_t i0 = pk < T(0) ? -1 : n_nodes - 1;
    const T f = pk - static_cast<T>(i0);
    T* o = ob + row * n_nodes;
    if (i0 >= 0) o[i0] += wk * (T(1) - f);
    if (i0 + 1 < n_nodes) o[i0 + 1] += wk * f;
  }
}

// Blocks taken together, position by position, when every block has a row of its own (all r = 0, step >= 1: a
// row per sample). Each row still takes its own block's arrivals in order, so the same sums; consecutive adds
// then go to kInterleave different rows instead of the same few nodes of one row, each waiting for the last.
constexpr int64_t kInterleave = 4;

template <typename T>
void Deposit(const T* p, const T* w, const int32_t* r, T* out, int64_t batch, int64_t n, int64_t period,
             int64_t step, int64_t n_rows, int64_t n_nodes) {
  const int64_t plane = n_rows * n_nodes;
  std::memset(out, 0, sizeof(T) * static_cast<size_t>(batch * plane));
  const T inner = static_cast<T>(n_nodes - 1);
  const T last = static_cast<T>(n_nodes);
  for (int64_t b = 0; b < batch; ++b) {
    const T* pb = p + b * n;
    const T* wb = w + b * n;
    const int32_t* rb = r + b * period;
    T* ob = out + b * plane;
    bool own_rows = step >= 1;
    for (int64_t i = 0; i < period && own_rows; ++i) own_rows = rb[i] == 0;
    int64_t start = 0, first = 0;
    if (own_rows) {
      for (; start + kInterleave * period <= n; start += kInterleave * period, first += kInterleave * step) {
        for (int64_t i = 0; i < period; ++i) {
          for (int64_t g = 0; g < kInterleave; ++g) {
            const int64_t k = start + g * period + i;
            Add(pb[k], wb[k], first + g * step, ob, n_rows, n_nodes, inner, last);
          }
        }
      }
    }
    for (; start < n; start += period, first += step) {  // blocks of L (one: N = L)
      for (int64_t i = 0; i < period; ++i) {
        Add(pb[start + i], wb[start + i], first + rb[i], ob, n_rows, n_nodes, inner, last);
      }
    }
  }
}

ffi::Error DepositImpl(ffi::AnyBuffer p, ffi::AnyBuffer w, ffi::Buffer<ffi::S32> r, ffi::Result<ffi::AnyBuffer> out,
                       int64_t n_rows, int64_t n_nodes, int64_t step) {
  const auto type = p.element_type();
  if (w.element_type() != type || out->element_type() != type) {
    return ffi::Error::InvalidArgument("nlosplan deposit: positions, weights and output must share one float type");
  }
  if (n_rows < 1 || n_nodes < 1) return ffi::Error::InvalidArgument("nlosplan deposit: empty output");
  const int64_t plane = n_rows * n_nodes;
  const int64_t total = static_cast<int64_t>(out->element_count());
  if (total % plane != 0) return ffi::Error::InvalidArgument("nlosplan deposit: output is not (B, n_rows, n_nodes)");
  const int64_t batch = total / plane;
  const int64_t count = static_cast<int64_t>(p.element_count());
  const int64_t n = count / batch;
  if (n == 0) {
    std::memset(out->untyped_data(), 0, out->size_bytes());
    return ffi::Error::Success();
  }
  const int64_t period = static_cast<int64_t>(r.element_count()) / batch;
  if (count % batch != 0 || static_cast<int64_t>(w.element_count()) != count || period < 1 || n % period != 0 ||
      static_cast<int64_t>(r.element_count()) != period * batch) {
    return ffi::Error::InvalidArgument("nlosplan deposit: positions, weights and rows differ in size");
  }
  if (type == ffi::F32) {
    Deposit(p.typed_data<float>(), w.typed_data<float>(), r.typed_data(), out->typed_data<float>(), batch, n, period,
            step, n_rows, n_nodes);
  } else if (type == ffi::F64) {
    Deposit(p.typed_data<double>(), w.typed_data<double>(), r.typed_data(), out->typed_data<double>(), batch, n,
            period, step, n_rows, n_nodes);
  } else {
    return ffi::Error::InvalidArgument("nlosplan deposit: float32 or float64 only");
  }
  return ffi::Error::Success();
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(NlosplanDeposit, DepositImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::Buffer<ffi::S32>>()
                                  .Ret<ffi::AnyBuffer>()
                                  .Attr<int64_t>("n_rows")
                                  .Attr<int64_t>("n_nodes")
                                  .Attr<int64_t>("step"));
