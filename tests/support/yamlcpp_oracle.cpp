// yaml-cpp's own conversions, for tests/test_yamlcpp.py: reads a YAML sequence of scalars on stdin and prints,
// per scalar, what node.as<T>() gives for bool, long long, unsigned long and double ("x" when it throws).
#include <cstdio>
#include <iostream>
#include <limits>
#include <string>
#include <yaml-cpp/yaml.h>

template <typename T, typename F>
void show(const YAML::Node &node, F print) {
  try {
    print(node.as<T>());
  } catch (const YAML::Exception &) {
    std::printf("x");
  }
}

int main() {
  const YAML::Node items = YAML::Load(std::cin);
  for (const auto &node : items) {
    show<bool>(node, [](bool v) { std::printf("%s", v ? "true" : "false"); });
    std::printf("\t");
    show<long long>(node, [](long long v) { std::printf("%lld", v); });
    std::printf("\t");
    show<unsigned long>(node, [](unsigned long v) { std::printf("%lu", v); });
    std::printf("\t");
    show<double>(node, [](double v) { std::printf("%.17g", v); });
    std::printf("\n");
  }
  return 0;
}
