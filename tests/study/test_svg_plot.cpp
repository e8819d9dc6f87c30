#include "study/progress.h"
#include "study/svg_plot.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <regex>
#include <string>

using namespace trephine::study;

namespace {

int countOf(const std::string& s, const std::string& what) {
    int n = 0;
    for (size_t p = s.find(what); p != std::string::npos; p = s.find(what, p + 1))
        ++n;
    return n;
}

} // namespace

TEST(NiceTicks, StepsOfOneTwoFive) {
    EXPECT_EQ(niceTicks(0, 10, 5), (std::vector<double>{0, 2, 4, 6, 8, 10}));
    EXPECT_EQ(niceTicks(10, 80, 8), (std::vector<double>{10, 20, 30, 40, 50, 60, 70, 80}));
    std::vector<double> t = niceTicks(0.013, 0.049, 4);
    ASSERT_FALSE(t.empty());
    EXPECT_GE(t.front(), 0.013 - 1e-12);
    EXPECT_LE(t.back(), 0.049 + 1e-12);
    EXPECT_EQ(niceTicks(3, 3, 5).size(), 1u);
}

TEST(SvgPlot, OnePolylineAndMarkerPerPointAndLegendEntry) {
    PlotSpec spec;
    spec.title = "Update rate <per> box & size";
    spec.xLabel = "box N";
    spec.yLabel = "updates/s";
    spec.series.push_back({"dbi", {10, 20, 30}, {900, 800, 700}, "", false});
    spec.series.push_back({"volume", {10, 20, 30}, {60, 58, 55}, "", true});
    const std::string svg = svgLinePlot(spec);
    EXPECT_EQ(svg.rfind("<svg", 0), 0u);
    EXPECT_NE(svg.find("</svg>"), std::string::npos);
    EXPECT_EQ(countOf(svg, "<polyline"), 2);
    EXPECT_EQ(countOf(svg, "<circle"), 6);
    EXPECT_EQ(countOf(svg, "stroke-dasharray"), 2); // the dashed series and its legend line
    EXPECT_NE(svg.find("&lt;per&gt; box &amp; size"), std::string::npos);
    EXPECT_EQ(svg.find("<per>"), std::string::npos);
    EXPECT_NE(svg.find(">dbi</text>"), std::string::npos);
    EXPECT_NE(svg.find(">volume</text>"), std::string::npos);
}

TEST(SvgPlot, HigherValuesDrawHigherAndLogSkipsNonPositive) {
    PlotSpec spec;
    spec.logY = true;
    spec.series.push_back({"s", {1, 2, 3}, {10, 1000, -1}, "#000", false});
    const std::string svg = svgLinePlot(spec);
    EXPECT_EQ(countOf(svg, "<circle"), 2); // -1 is skipped on a log axis
    std::smatch m;
    std::regex circle(R"re(<circle cx="([0-9.]+)" cy="([0-9.]+)")re");
    std::vector<double> ys;
    for (auto it = std::sregex_iterator(svg.begin(), svg.end(), circle);
         it != std::sregex_iterator(); ++it)
        ys.push_back(std::stod((*it)[2]));
    ASSERT_EQ(ys.size(), 2u);
    EXPECT_LT(ys[1], ys[0]); // SVG y grows downwards: 1000 sits above 10
    EXPECT_NE(svg.find(">1000<"), std::string::npos);
}

TEST(SvgPlot, EmptyPlotStillDrawsAxes) {
    PlotSpec spec;
    spec.title = "nothing";
    const std::string svg = svgLinePlot(spec);
    EXPECT_NE(svg.find("<rect"), std::string::npos);
    EXPECT_EQ(countOf(svg, "<circle"), 0);
}

TEST(MarkdownTable, HeaderAlignmentRowsAndEscapedPipes) {
    const std::string md = markdownTable({"box", "dbi"}, {{"10^3", "a|b"}, {"20^3"}});
    EXPECT_EQ(md, "| box | dbi |\n|---|---:|\n| 10^3 | a\\|b |\n| 20^3 |  |\n");
}

TEST(ProgressBar, DrawsInPlaceOnlyWhenEnabled) {
    char* buffer = nullptr;
    size_t size = 0;
    std::FILE* f = open_memstream(&buffer, &size);
    ASSERT_NE(f, nullptr);
    {
        ProgressBar bar(4, 1, f);
        bar.step("dbi 10^3");
        bar.step("dbi 20^3");
        EXPECT_EQ(bar.done(), 2);
        EXPECT_NE(bar.line().find(" 50%"), std::string::npos);
        EXPECT_NE(bar.line().find("dbi 20^3"), std::string::npos);
        bar.set(99, "past the end");
        EXPECT_EQ(bar.done(), 4);
    }
    std::fflush(f);
    const std::string drawn(buffer, size);
    std::fclose(f);
    std::free(buffer);
    EXPECT_EQ(countOf(drawn, "\r"), 4); // three draws and the final clear
    EXPECT_NE(drawn.find("[###############...............]"), std::string::npos);

    buffer = nullptr;
    size = 0;
    f = open_memstream(&buffer, &size);
    {
        ProgressBar quiet(4, 0, f);
        quiet.step("x");
    }
    std::fflush(f);
    EXPECT_EQ(size, 0u);
    std::fclose(f);
    std::free(buffer);
}

TEST(SvgPlot, LargeTicksReadAsThousandsAndMillions) {
    PlotSpec spec;
    spec.logY = true;
    spec.series.push_back({"bytes", {10, 80}, {1000, 512000}, "", false});
    const std::string svg = svgLinePlot(spec);
    EXPECT_NE(svg.find(">1M<"), std::string::npos);
    EXPECT_NE(svg.find(">10k<"), std::string::npos);
    EXPECT_NE(svg.find(">1000<"), std::string::npos);
}
