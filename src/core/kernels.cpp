#include "core/kernels.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace ganache {

CubicSpline::CubicSpline(Real supportRadius) : m_h(supportRadius), m_invH(1 / supportRadius) {
    if (!(supportRadius > 0) || !std::isfinite(supportRadius))
        throw std::invalid_argument("CubicSpline: support radius must be positive and finite");
    const Real h3 = m_h * m_h * m_h;
    m_k = Real(8) / (Real(M_PI) * h3);
    m_l = Real(48) / (Real(M_PI) * h3);
}

void CubicSpline::valuesAndGradients(std::size_t n, Real* r2, Real* w) const {
    const Real tiny = Real(1e-12) * m_h;
    for (std::size_t p = 0; p < n; ++p) {
        const Real r = std::sqrt(r2[p]);
        const Real q = r * m_invH, a = 1 - q;
        const bool inner = q <= Real(0.5), outside = q >= 1;
        const Real value = inner ? m_k * (6 * q * q * (q - 1) + 1) : 2 * m_k * a * a * a;
        const Real dWdq = inner ? m_l * q * (3 * q - 2) : -m_l * (1 - q) * (1 - q);
        const Real g = dWdq * m_invH / std::max(r, tiny);  // max: no division by zero in lanes that take 0
        w[p] = outside ? 0 : value;
        r2[p] = (outside | (r < tiny)) ? 0 : g;
    }
}

Real latticeKernelSum(Real spacing, const CubicSpline& w) {
    const int m = int(std::ceil(w.supportRadius() / spacing));
    Real sum = 0;
    for (int k = -m; k <= m; ++k)
        for (int j = -m; j <= m; ++j)
            for (int i = -m; i <= m; ++i) sum += w.W(spacing * Vec3(i, j, k));
    return sum;
}

}  // namespace ganache
