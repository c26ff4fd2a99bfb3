#include <iostream>
int main() { std::cout << "scalefuse\n"; return 0; }
