fn main() {
    println!("svetlo");
}
