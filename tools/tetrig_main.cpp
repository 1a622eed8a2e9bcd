#include <cstdio>
int main() { std::puts("tetrig: under construction"); return 0; }
