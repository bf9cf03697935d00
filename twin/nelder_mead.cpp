// twin layer — the bounded Nelder–Mead minimiser (see nelder_mead.hpp): the textbook
// coefficients (reflection 1, expansion 2, contraction ½, shrink ½), points projected onto
// the unit box, every evaluation recorded.
#include "twin/nelder_mead.hpp"

#include <algorithm>
#include <numeric>
#include <stdexcept>

namespace omnitwin::twin {

namespace {

using Point = std::vector<double>;

Point clamp_box(Point x) {
  for (double& v : x) v = std::clamp(v, 0.0, 1.0);
  return x;
}

// a + t·(b − a), projected onto the box.
Point along(const Point& a, const Point& b, double t) {
  Point p(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) p[i] = a[i] + t * (b[i] - a[i]);
  return clamp_box(p);
}

// The simplex with its values, kept sorted best first.
struct Simplex {
  std::vector<Point> x;
  std::vector<double> f;
  void sort() {
    std::vector<std::size_t> order(x.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return f[a] < f[b]; });
    std::vector<Point> xs;
    std::vector<double> fs;
    for (std::size_t i : order) xs.push_back(x[i]), fs.push_back(f[i]);
    x = std::move(xs), f = std::move(fs);
  }
  // Centroid of every vertex but the worst.
  Point centroid() const {
    Point c(x.front().size(), 0.0);
    for (std::size_t v = 0; v + 1 < x.size(); ++v)
      for (std::size_t i = 0; i < c.size(); ++i) c[i] += x[v][i] / static_cast<double>(x.size() - 1);
    return c;
  }
};

}  // namespace

NelderMeadResult nelder_mead(const std::function<double(const std::vector<double>&)>& f, std::vector<double> x0,
                             const NelderMeadOptions& options) {
  const std::size_t n = x0.size();
  if (n == 0) throw std::invalid_argument("nelder_mead: no parameters");
  if (options.max_evaluations < static_cast<int>(n) + 1)
    throw std::invalid_argument("nelder_mead: the budget cannot evaluate one simplex");
  NelderMeadResult r;
  auto eval = [&](const Point& p) {
    const double v = f(p);
    r.trace.push_back({p, v});
    ++r.evaluations;
    return v;
  };
  // Starting simplex: x0 and one step along each axis (backwards where the box ends).
  Simplex s;
  s.x.push_back(clamp_box(std::move(x0)));
  for (std::size_t i = 0; i < n; ++i) {
    Point p = s.x.front();
    p[i] += p[i] + options.initial_step <= 1.0 ? options.initial_step : -options.initial_step;
    s.x.push_back(clamp_box(p));
  }
  for (const Point& p : s.x) s.f.push_back(eval(p));
  s.sort();
  while (r.evaluations < options.max_evaluations) {
    if (s.f.back() - s.f.front() < options.tolerance) {
      r.converged = true;
      break;
    }
    const Point c = s.centroid();
    const Point reflected = along(s.x.back(), c, 2.0);
    const double fr = eval(reflected);
    if (fr < s.f.front()) {
      // Better than the best: try going twice as far.
      const Point expanded = along(s.x.back(), c, 3.0);
      const double fe = r.evaluations < options.max_evaluations ? eval(expanded) : fr + 1.0;
      if (fe < fr)
        s.x.back() = expanded, s.f.back() = fe;
      else
        s.x.back() = reflected, s.f.back() = fr;
    } else if (fr < s.f[n - 1]) {
      // Better than the second worst: keep the reflection.
      s.x.back() = reflected, s.f.back() = fr;
    } else {
      // Contract towards the centroid, from whichever side is better.
      const bool outside = fr < s.f.back();
      const Point contracted = outside ? along(s.x.back(), c, 1.5) : along(s.x.back(), c, 0.5);
      const double fc = r.evaluations < options.max_evaluations ? eval(contracted) : s.f.back() + 1.0;
      if (fc < std::min(fr, s.f.back())) {
        s.x.back() = contracted, s.f.back() = fc;
      } else {
        // Shrink every vertex halfway towards the best.
        for (std::size_t v = 1; v <= n && r.evaluations < options.max_evaluations; ++v) {
          s.x[v] = along(s.x.front(), s.x[v], 0.5);
          s.f[v] = eval(s.x[v]);
        }
      }
    }
    s.sort();
  }
  r.x = s.x.front();
  r.value = s.f.front();
  return r;
}

}  // namespace omnitwin::twin
