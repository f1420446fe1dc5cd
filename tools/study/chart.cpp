// Log-log charts for `ganache study`, drawn with the same pixel font as the preview legends.

#include "tools/study/chart.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace ganache {

namespace {

const Vec3 kInk(0.1, 0.1, 0.1);
const Vec3 kGrid(0.85, 0.85, 0.85);

void dot(Image& image, int x, int y, int half, const Vec3& colour) {
    fillRect(image, x - half, y - half, x + half + 1, y + half + 1, colour);
}

// A line of the given thickness, stepped one pixel at a time along its longer axis.
void line(Image& image, Real x0, Real y0, Real x1, Real y1, int half, const Vec3& colour) {
    const int steps = std::max(1, int(std::ceil(std::max(std::abs(x1 - x0), std::abs(y1 - y0)))));
    for (int s = 0; s <= steps; ++s) {
        const Real t = Real(s) / steps;
        dot(image, int(std::lround(x0 + t * (x1 - x0))), int(std::lround(y0 + t * (y1 - y0))), half, colour);
    }
}

std::string decadeLabel(int exponent) {
    if (exponent >= -2 && exponent <= 3) return fmt::format("{:g}", std::pow(10.0, exponent));
    return fmt::format("1e{}", exponent);
}

}  // namespace

Vec3 seriesColour(std::size_t index) {
    static const Vec3 colours[] = {{0.12, 0.47, 0.71}, {1.00, 0.50, 0.05}, {0.17, 0.63, 0.17}, {0.84, 0.15, 0.16},
                                   {0.58, 0.40, 0.74}, {0.55, 0.34, 0.29}, {0.89, 0.47, 0.76}, {0.50, 0.50, 0.50},
                                   {0.74, 0.74, 0.13}, {0.09, 0.75, 0.81}};
    return colours[index % (sizeof(colours) / sizeof(colours[0]))];
}

Image logLogChart(const Chart& chart) {
    Image image;
    image.width = chart.width;
    image.height = chart.height;
    image.rgb.assign(std::size_t(chart.width) * chart.height * 3, 255);
    const int scale = 2;
    const int left = 110, right = chart.width - 330, top = 60, bottom = chart.height - 80;

    Real xLo = std::numeric_limits<Real>::infinity(), xHi = -xLo, yLo = xLo, yHi = -xLo;
    auto usable = [](const std::pair<Real, Real>& p) {
        return std::isfinite(p.first) && std::isfinite(p.second) && p.first > 0 && p.second > 0;
    };
    for (const auto& s : chart.series)
        for (const auto& p : s.points)
            if (usable(p)) {
                xLo = std::min(xLo, std::log10(p.first));
                xHi = std::max(xHi, std::log10(p.first));
                yLo = std::min(yLo, std::log10(p.second));
                yHi = std::max(yHi, std::log10(p.second));
            }
    if (!std::isfinite(xLo)) xLo = yLo = 0, xHi = yHi = 1;
    const int dx0 = int(std::floor(xLo)), dx1 = std::max(dx0 + 1, int(std::ceil(xHi)));
    const int dy0 = int(std::floor(yLo)), dy1 = std::max(dy0 + 1, int(std::ceil(yHi)));
    auto px = [&](Real x) { return left + (std::log10(x) - dx0) / (dx1 - dx0) * (right - left); };
    auto py = [&](Real y) { return bottom - (std::log10(y) - dy0) / (dy1 - dy0) * (bottom - top); };

    // Grid and decade labels.
    for (int e = dx0; e <= dx1; ++e) {
        const int x = int(std::lround(px(std::pow(10.0, e))));
        fillRect(image, x, top, x + 1, bottom, kGrid);
        const std::string label = decadeLabel(e);
        drawText(image, x - int(label.size()) * 6 * scale / 2, bottom + 10, label, kInk, scale);
    }
    for (int e = dy0; e <= dy1; ++e) {
        const int y = int(std::lround(py(std::pow(10.0, e))));
        fillRect(image, left, y, right, y + 1, kGrid);
        const std::string label = decadeLabel(e);
        drawText(image, left - 10 - int(label.size()) * 6 * scale, y - 7, label, kInk, scale);
    }
    fillRect(image, left, top, right, top + 2, kInk);
    fillRect(image, left, bottom - 1, right, bottom + 1, kInk);
    fillRect(image, left - 1, top, left + 1, bottom, kInk);
    fillRect(image, right - 1, top, right + 1, bottom, kInk);
    drawText(image, left, 8, chart.title, kInk, scale + 1);
    drawText(image, (left + right) / 2 - int(chart.xLabel.size()) * 6 * scale / 2, bottom + 42, chart.xLabel, kInk,
             scale);
    drawText(image, 8, top - 22, chart.yLabel, kInk, scale);

    // Series, then the legend to the right of the plot.
    for (std::size_t k = 0; k < chart.series.size(); ++k) {
        const ChartSeries& s = chart.series[k];
        bool havePrevious = false;
        Real previousX = 0, previousY = 0;
        for (std::size_t i = 0; i < s.points.size(); ++i) {
            if (!usable(s.points[i])) continue;
            const Real x = px(s.points[i].first), y = py(s.points[i].second);
            if (havePrevious) line(image, previousX, previousY, x, y, 1, s.colour);
            havePrevious = true;
            previousX = x;
            previousY = y;
        }
        for (std::size_t i = 0; i < s.points.size(); ++i) {
            if (!usable(s.points[i])) continue;
            const int x = int(std::lround(px(s.points[i].first))), y = int(std::lround(py(s.points[i].second)));
            dot(image, x, y, 5, kInk);
            dot(image, x, y, 4, s.colour);
            if (i < s.pointLabels.size()) drawText(image, x + 8, y - 14, s.pointLabels[i], s.colour * 0.7, 1);
        }
        const int ly = top + 10 + int(k) * 26;
        fillRect(image, right + 20, ly, right + 44, ly + 14, s.colour);
        drawText(image, right + 52, ly, s.label, kInk, scale);
    }
    return image;
}

}  // namespace ganache
